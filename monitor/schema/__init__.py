"""The one schema engine of both YAML files (config/monitor.yaml, config/simulator.yaml):
a strict YAML reader and typed sections checked from dataclass field metadata."""
