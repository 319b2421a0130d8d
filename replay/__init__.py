"""Package data (installed as monitor.resources.replay); see monitor/resources."""
