"""The augmentation: a reference run's renders become training data for any target method."""
