"""Typed errors a person can cause; each message says what happened and what to do next."""


class FixwizardError(Exception):
    """Base class for errors caused by input, files or the cell, shown to the operator as is."""


class InputError(FixwizardError):
    """A file, argument or value the operator supplied cannot be used."""


class MeshError(InputError):
    """The fixture mesh file cannot be used (not a mesh, empty, implausible units)."""
