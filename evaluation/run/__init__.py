"""Playing, resuming and checking runs: what ``unitrack evaluate`` does to a run folder.

* :mod:`.runner` - :func:`~.runner.run`, an agent over every sequence of an environment;
* :mod:`.episode` - the one episode loop (``play_episode``) and a sequence's record;
* :mod:`.serial`, :mod:`.workers`, :mod:`.pool`, :mod:`.watchdog`, :mod:`.backends`,
  :mod:`.ray_sequences` - where sequences play (here, supervised worker processes, Ray) and
  the per-step time limit;
* :mod:`.ownership`, :mod:`.resume`, :mod:`.restamp`, :mod:`.identity`, :mod:`.run_spec`,
  :mod:`.agent_code`, :mod:`.integrity` - who owns a folder, which finished sequences a rerun
  keeps, and whether stored metrics still describe their files;
* :mod:`.repetitions` - the spread over ``--repeats``; :mod:`.progress` - the progress bar
  and the package's one-line warnings.
"""
