"""The `workbench` command line: argument parsing and printing only (`main.main` is the entry point)."""
