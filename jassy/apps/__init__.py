"""Applications: the command line, benches, checks, documentation, previews."""
