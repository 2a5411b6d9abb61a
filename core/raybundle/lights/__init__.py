"""Light sources, their analytic irradiance, the direct-lighting estimator and the first shots."""
