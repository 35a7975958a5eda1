"""The command line: parser, handlers, progress bar."""
