"""Command-line interface (``orokit ...``). One module per command."""
