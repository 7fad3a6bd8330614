"""dear_train: training and ONNX export of the DEAR networks (see ``train/README.md``)."""

__version__ = "0.1.0"
