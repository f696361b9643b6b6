"""DataManagers: turn a parsed dataset into training batches (rays or whole images)."""
