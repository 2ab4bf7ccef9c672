"""The papers' design tools as a library (see each module)."""
