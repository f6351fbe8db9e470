"""Files in and out: output directories as transactions, paths, JSON."""
