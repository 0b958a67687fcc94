"""The ``orokit`` process leaves without the interpreter's teardown (numba's costs ~0.3 CPU s), yet
with the exit status, flushed output and exit handlers of a normal exit."""
from __future__ import annotations

import subprocess
import sys

import pytest

#: a process running the CLI as the console script does (``cli()`` without arguments); an object
#: whose finalizer prints shows whether the interpreter was torn down
SCRIPT = """
import atexit, sys, threading, time
from orokit.cli.main import cli
class Probe:
    def __del__(self):
        print("torn down", flush=True)
probe = Probe()
atexit.register(lambda: print("exit handlers ran"))
if sys.argv[1] == "thread":  # a non-daemon thread still running at the end: the normal exit waits for it
    threading.Thread(target=time.sleep, args=(0.5,)).start()
sys.argv = ["orokit", *sys.argv[2:]]
cli()
"""


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True, text=True, timeout=120)


def test_console_exit_skips_the_teardown_but_not_the_exit_handlers():
    res = _run("plain", "--version")
    assert res.returncode == 0
    # stdout is a pipe (block-buffered): the version line is there only because it was flushed
    assert res.stdout.splitlines() == ["orokit, version " + _version(), "exit handlers ran"]


def test_console_exit_keeps_the_status_and_stderr_of_an_error():
    res = _run("plain", "no-such-command")
    assert res.returncode == 2
    assert "No such command 'no-such-command'" in res.stderr
    assert res.stdout.splitlines() == ["exit handlers ran"]


def test_console_exit_waits_for_a_running_thread():
    res = _run("thread", "--version")
    assert res.returncode == 0
    assert res.stdout.splitlines() == ["orokit, version " + _version(), "exit handlers ran", "torn down"]


def test_in_process_call_with_arguments_returns():
    """``cli([...], standalone_mode=False)`` (scripts, tests) is click's plain call: no exit at all."""
    code = ("from orokit.cli.main import cli\n"
            "cli(['--help'], standalone_mode=False)\n"
            "print('still here')\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert res.stdout.splitlines()[-1] == "still here"


def _version() -> str:
    from orokit import __version__

    return __version__


#: the main thread starts or joins a thread that still works (as scipy's ``cKDTree.query(workers=-1)`` does, its
#: threads searching a tree the caller frees once that raises) when one or two signals come; prints what the
#: thread had done by then
JOIN = """
import os, signal, sys, threading, time
from orokit.cli import main
done = []
class SlowStart(threading.Thread):  # Thread.start waits for the thread to begin
    def _bootstrap_inner(self):
        time.sleep(4.0)  # long beside the signals at 0.3 / 0.6 s, so a loaded machine cannot blur them
        done.append(1)
        super()._bootstrap_inner()
main._catch_signals()
for at in (0.3, 0.6)[:int(sys.argv[3])]:  # a second signal: at once
    threading.Timer(at, os.kill, (os.getpid(), getattr(signal, sys.argv[1]))).start()
try:
    if sys.argv[2] == "join":
        worker = threading.Thread(target=lambda: (time.sleep(4.0), done.append(1)), daemon=True)
        worker.start()
        worker.join()
    else:
        SlowStart(target=time.sleep, args=(0,), daemon=True).start()
    time.sleep(2)  # the interrupt comes after the join
    print("no interrupt")
except KeyboardInterrupt as exc:
    print(type(exc).__name__, "thread done" if done else "thread running", flush=True)
"""


@pytest.mark.parametrize("wait", ["join", "start"])
def test_a_signal_waits_for_the_threads_being_started_or_joined(wait):
    """Ctrl-C in ``orokit render`` while scipy's query started or joined its threads crashed the process
    (segmentation fault, exit 139: the threads searched a freed tree); the interrupt now comes after, and a
    second one at once."""
    for name, kind in (("SIGINT", "KeyboardInterrupt"), ("SIGTERM", "_Terminated")):
        for signals, state in ((1, "done"), (2, "running")):
            res = subprocess.run([sys.executable, "-c", JOIN, name, wait, str(signals)], capture_output=True,
                                 text=True, timeout=120)
            assert res.returncode == 0, res.stderr
            assert res.stdout.split() == [kind, "thread", state]
            assert "stopping once the running threads are done" in res.stderr
