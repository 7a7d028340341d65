"""Run records: the run folder, data files, summaries and plots (off the hot path)."""
