"""The `livezmp` subcommands, one module each; :mod:`livezmp.cli` assembles them."""
