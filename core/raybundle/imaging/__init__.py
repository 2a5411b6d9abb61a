"""Camera images and bakes from a solution: settings, the renderer, the run loop, the final gather."""
