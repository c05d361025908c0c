"""The paper's evaluations as library functions: registration tables (I, II), the
precision curve (Fig. 4), descriptor matching (Table III) and the report that
`experiments.evaluate` writes (evaluators.py names them). Per-cloud keypoints and descriptors are shared
between them through `feature_store.FeatureStore`."""
