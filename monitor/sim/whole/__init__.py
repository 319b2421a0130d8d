"""The whole excavator: boom, stick, bucket and swing on one load-sensing pump (issue 39)."""
