"""Loading a trained run back: its method is found by name in the registry, so this sits above it.
``load`` rebuilds the pipeline (eval, viewer, the augmentation's reference); ``model`` only the model
(export, without the dataset)."""
