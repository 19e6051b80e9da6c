"""glsynth: synthetic environments of Japanese RC railway viaducts (the Tokaido dataset paper),
generated from seeds and rendered headless with OpenGL."""

__version__ = "0.1.0"
