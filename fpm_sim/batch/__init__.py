"""The pose loop and its backends (cpu; jax: MuJoCo's formulas in JAX; mjx: MJX's pipeline)."""
