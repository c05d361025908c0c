"""Adapting a model to a drive without labels: mining training pairs with the classical
path and widening them with the model trained so far (`mining`), and choosing where an
adapted model's keypoints are sampled (`keypoint_choice`). The mined pairs' file format
is `ssd_jax.data.mined_pairs`, which training reads."""
