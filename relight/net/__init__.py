"""The paper's regression network (Sial et al.): model, loss, data, training,
evaluation and prediction. Import submodules directly (``relight.net.predict``);
this package imports nothing heavy by itself."""

__all__ = [
    "calibrate", "data", "evaluate", "io", "loss", "model", "predict", "train", "uncertainty",
]
