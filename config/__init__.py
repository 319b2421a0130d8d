"""Package data (installed as monitor.resources.config); see monitor/resources."""
