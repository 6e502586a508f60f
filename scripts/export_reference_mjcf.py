"""Regenerate the MJCF files checked into mjcf/ (run after any change to model generation)."""

from pathlib import Path

from fpm_sim.model.mjcf_export import write_reference_mjcf

if __name__ == "__main__":
    for p in write_reference_mjcf(Path(__file__).resolve().parent.parent / "mjcf"):
        print(f"wrote {p}")
