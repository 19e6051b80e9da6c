"""Datasets: filters, RRDR masking, plates, the Tokaido layout (written and read), generation
engines and run folders."""
