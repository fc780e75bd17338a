"""Reference generation: ruckig moves and soft stop, file playback, the benchmark trajectory."""
