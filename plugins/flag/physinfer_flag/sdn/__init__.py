"""The Spectral Decomposition Network (SDN): the flag plugin's learned embedding.

Modules (import them directly; this package imports nothing heavy):

- :mod:`~physinfer_flag.sdn.spectral`: the spectral decomposition layer (Algorithm 1).
- :mod:`~physinfer_flag.sdn.frontend`: the fixed front end and its feature cache.
- :mod:`~physinfer_flag.sdn.network`: :class:`~physinfer_flag.sdn.network.SDN`.
- :mod:`~physinfer_flag.sdn.weights`: the weights file, ``save_sdn``/``load_sdn``.
- :mod:`~physinfer_flag.sdn.losses`: the contrastive loss with Batch All mining.
- :mod:`~physinfer_flag.sdn.data`: the dataset interface; :mod:`~physinfer_flag.sdn.synthetic`:
  tiny moving-grating datasets.
- :mod:`~physinfer_flag.sdn.training`: ``train_sdn`` (resumable, best model kept).
- :mod:`~physinfer_flag.sdn.evaluation`: triplet accuracy, wind-speed regression.
- :mod:`~physinfer_flag.sdn.baselines`: multi-frame ResNet-18, CNN+LSTM, spectral pooling.
- :mod:`~physinfer_flag.sdn.embedder`: ``SDNEmbedder`` and ``SpectralEmbedder``.
"""
