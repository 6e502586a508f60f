"""The study's data and poses, its reproduction, identification, readability, transient."""
