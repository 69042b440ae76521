"""The paper's regression network (Sial et al.): model, loss, data, training,
evaluation and prediction. Import submodules directly (``relight.net.predict``);
this package imports nothing heavy by itself."""
