"""Built-in scenario files (YAML): demo, baseline-10km, network-70km, iono-storm."""
