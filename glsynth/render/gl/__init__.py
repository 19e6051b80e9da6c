"""Everything that touches OpenGL lives in this package."""
