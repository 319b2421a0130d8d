"""Reading recordings for the offline tools as the daemon would see them on the bus."""
