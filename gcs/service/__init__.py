"""The long-lived side of the coordinator: the fleet of vehicle links its flights share."""
