"""Reports of runs and benchmarks: floor plans (`floorplan`), and later HTML pages, tables, plots and videos."""
