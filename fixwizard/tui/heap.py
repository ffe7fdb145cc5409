"""The wizard process's garbage collector, kept off the event loop's back."""

import gc


def freeze_long_lived_objects() -> None:
    """Take every object alive now (the imports', the fixtures', the app's) out of the collector's full passes.

    A full collection walks every tracked object: with open3d, scipy, numba and Textual imported (about 200 000)
    one took 70-230 ms on the event loop, a key left unanswered that long. Frozen objects are no longer walked; they
    are still freed when nothing refers to them (``gc.unfreeze`` returns them)."""
    gc.collect()  # what is garbage already is not frozen
    gc.freeze()
