"""The test suite, laid out by the package it tests (a package each, so equal file names in two folders do not collide)."""
