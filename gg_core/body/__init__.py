"""Body models (a shipped anny body, SMPL-X from user files), linear blend skinning, and procedural motions."""
