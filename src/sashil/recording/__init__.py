"""Run records: data files, summaries, plots, formats and traces (off the hot path); the run folder and its writer are :mod:`sashil.writer`."""
