"""Reports: results -> CSV, one self-contained HTML page, VTU/PVD exports."""
