"""Tests of the completion library `lsc`."""
