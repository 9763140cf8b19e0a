"""Stage 1 of the pipeline: what is rendered (meshes, materials, lights, camera)."""
