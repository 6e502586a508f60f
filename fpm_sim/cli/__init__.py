"""The command line: one module per command plus shared options and error handling."""
