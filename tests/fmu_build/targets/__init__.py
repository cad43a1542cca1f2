"""Tests of `fmu_build.targets`: pythonfmu and native (C) FMUs, FMI 2.0 and 3.0, constant and time-varying, with inputs, in our hosts and in hosts nobody here wrote."""
