"""Fuzzing every input format livezmp reads (issue 12): ``harness`` builds seeds, mutates
them and checks the contract; ``test_fuzz`` is the bounded CI part (hypothesis);
``python -m tests.fuzz --minutes N`` is the longer run printing a table per format."""
