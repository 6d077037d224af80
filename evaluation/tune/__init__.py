"""``unitrack tune``: a hyper-parameter search over a head's options.

* :mod:`.search` - the search space, one trial (a run on the tuning split), the search on
  Optuna and the validation of the best setting against the defaults (:func:`~.search.tune`);
* :mod:`.ray_trials` - the same trials as Ray Tune trials (``--backend ray``).
"""
