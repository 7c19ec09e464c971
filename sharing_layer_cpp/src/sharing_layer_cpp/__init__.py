"""Python face of the sharing layer's C++ core (see core.py)."""
