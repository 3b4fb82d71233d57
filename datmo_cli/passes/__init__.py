"""The passes that turn a log into a log (pipeline layer): the stages as channels (stages, feature_channels),
streaming them over a log (streaming), `datmo run`'s pass (pipeline), the single-stage passes (stage_files),
the configuration tree (config) and the logs they read (input_logs, simulated)."""
