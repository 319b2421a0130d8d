"""Package data (installed as monitor.resources.dbc); see monitor/resources."""
