"""Array helpers and image files: what every layer above uses."""
