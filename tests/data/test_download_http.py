"""Downloads through the real HTTP path (pooch) from a local server on 127.0.0.1.

The server serves a good file, a file whose bytes were altered, and a response that
promises more bytes than it sends and closes mid-body. Nothing may land under the
final name unless the bytes match the manifest's sha256.
"""
from __future__ import annotations

import hashlib
import http.server
import threading

import pytest

from orokit.io.fetch import fetch_file
from orokit.io.manifest import DataFile
from orokit.errors import DataError

GOOD = b"orokit test payload\n" * 2000


class _Handler(http.server.BaseHTTPRequestHandler):
    def do_GET(self):  # noqa: N802 - http.server API
        if self.path == "/good.bin":
            body = GOOD
        elif self.path == "/altered.bin":
            body = GOOD[:-1] + b"?"
        elif self.path == "/truncated.bin":
            self.send_response(200)
            self.send_header("Content-Length", str(len(GOOD)))
            self.end_headers()
            self.wfile.write(GOOD[: len(GOOD) // 3])
            self.wfile.flush()
            self.close_connection = True
            return
        else:
            self.send_error(404)
            return
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):  # keep the test output quiet
        pass


@pytest.fixture(scope="module")
def server():
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    t = threading.Thread(target=httpd.serve_forever, daemon=True)
    t.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


def _entry(url: str) -> DataFile:
    return DataFile(path="test/payload.bin", url=url, sha256=hashlib.sha256(GOOD).hexdigest())


def test_good_download_lands_with_its_hash(server, tmp_path):
    path = fetch_file(_entry(f"{server}/good.bin"), cache_dir=tmp_path, mirror=False)
    assert path.read_bytes() == GOOD
    assert [p.name for p in path.parent.iterdir() if not p.name.startswith(".")] == ["payload.bin"]


def test_altered_bytes_are_refused_and_nothing_lands(server, tmp_path):
    with pytest.raises(DataError, match="sha256 mismatch") as err:
        fetch_file(_entry(f"{server}/altered.bin"), cache_dir=tmp_path, mirror=False)
    assert hashlib.sha256(GOOD).hexdigest() in str(err.value)
    assert not (tmp_path / "test" / "payload.bin").exists()
    assert not [p for p in (tmp_path / "test").iterdir() if "tmp" in p.name]


def test_interrupted_body_leaves_nothing_and_keeps_an_older_good_copy(server, tmp_path, monkeypatch):
    import sys

    fetch_module = sys.modules["orokit.io.fetch"]  # (orokit.io.fetch is also a function name)
    monkeypatch.setattr(fetch_module.time, "sleep", lambda s: None)  # retries without waiting
    with pytest.raises(DataError, match="cannot download|sha256 mismatch"):
        fetch_file(_entry(f"{server}/truncated.bin"), cache_dir=tmp_path, mirror=False)
    assert not (tmp_path / "test" / "payload.bin").exists()
    assert not [p for p in (tmp_path / "test").iterdir() if "tmp" in p.name]
    # a good copy already in the cache survives a failed forced re-download
    good = fetch_file(_entry(f"{server}/good.bin"), cache_dir=tmp_path, mirror=False)
    with pytest.raises(DataError):
        fetch_file(_entry(f"{server}/truncated.bin"), cache_dir=tmp_path, mirror=False, force=True)
    assert good.read_bytes() == GOOD
