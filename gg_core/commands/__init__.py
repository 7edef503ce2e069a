"""Thin CLI adapters: parse options, call the domain/stage code, print results."""
