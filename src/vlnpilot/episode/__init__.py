"""One closed-loop episode, the paper's Python controller: `loop` (run_episode), `config` (EpisodeConfig, the
outcomes), `ask` (asking and validating the pilot), `measures`, `record` (one line of episode.jsonl each step),
`run` (a run directory around an episode), `overrides`."""
