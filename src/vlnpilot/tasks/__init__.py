"""What counts: the task or mission a query asks for, the success monitor and its thresholds, paths and SPL."""
