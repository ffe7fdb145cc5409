"""The steps of the job as plain Python, shared by the CLI and the wizard."""
