"""The C++ core of the sharing layer, as NumPy-friendly Python objects.

Everything here is implemented in C++ (module ``_sharing_core``); this module only
re-exports it so that callers write ``from sharing_layer_cpp import core``.
"""
from sharing_layer_cpp._sharing_core import *  # noqa: F401,F403
from sharing_layer_cpp._sharing_core import __doc__  # noqa: F401
