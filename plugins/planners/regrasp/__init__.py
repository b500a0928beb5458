"""Three-layer regrasp graph: start pose, intermediate placements, goal pose."""
