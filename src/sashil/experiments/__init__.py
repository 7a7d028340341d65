"""Experiment plans (drop test, sweep, bench run): what to command and when, apart from devices and recording."""
