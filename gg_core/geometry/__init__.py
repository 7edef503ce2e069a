"""Triangle-mesh geometry: file I/O, topology, remeshing, UV atlases, ray casting."""
