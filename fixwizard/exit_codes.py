"""The ``fixwizard`` command's exit codes: what a script may rely on. Only 0 means a pose a robot program can use."""

EXIT_OK, EXIT_BAD_INPUT, EXIT_INCONSISTENT, EXIT_AMBIGUOUS, EXIT_UNDETERMINED, EXIT_CANCELLED = 0, 1, 2, 3, 4, 130
EXIT_READER_GONE = 141  # what reads the standard output went away (``| head``): 128 + SIGPIPE, as a shell says it
# solve: one per status
EXIT_CODES = {"unique": EXIT_OK, "inconsistent": EXIT_INCONSISTENT, "ambiguous": EXIT_AMBIGUOUS,
              "undetermined": EXIT_UNDETERMINED}
