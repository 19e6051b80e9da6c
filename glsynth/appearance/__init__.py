"""How parts look: the texture repository, materials, procedural damage and the dressing of an
environment. Pure numpy; imports glsynth.core and glsynth.world."""
