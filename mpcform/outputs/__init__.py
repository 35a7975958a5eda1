"""What a run writes and shows: files, run data, plots, comparisons, exports, tables."""
