"""The execution environment: device and thread choice, safe interrupts, lazy imports, provenance."""
