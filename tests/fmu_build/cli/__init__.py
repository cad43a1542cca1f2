"""Tests of the `lsc-fmu` command line."""
