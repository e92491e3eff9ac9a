"""The user-facing scenario YAMLs, sweep files, and their typed schemas and loader.

Imports nothing else of the project."""
