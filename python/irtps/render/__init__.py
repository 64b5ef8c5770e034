"""Rendering a reconstruction in its surroundings, and what follows from a rendering."""
