"""The guaranteed pose-set search and the estimates drawn from it; no I/O, no UI."""
