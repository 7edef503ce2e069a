"""Capture folders: layout, cameras, images, validation, importers from other layouts."""
