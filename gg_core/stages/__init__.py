"""Pipeline stages: each reads the previous stage's files and writes its own outputs and report."""
