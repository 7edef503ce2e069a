"""Evaluation metrics (REFERENCE §7): surface distances between meshes, image and behaviour errors."""
