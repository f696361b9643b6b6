"""Model and Pipeline contracts, the Trainer, callbacks, optimizers, checkpoints and configs."""
