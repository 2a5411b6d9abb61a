"""The scene: triangles, materials, textures, camera, lights as records, its file format and the built-in scenes."""
