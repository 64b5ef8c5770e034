"""Height fields: integration of normals, the surface, the placement on the floor."""
