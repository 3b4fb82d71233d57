"""Scene simulation: ray casting, walking model, scenes and ground truth."""
