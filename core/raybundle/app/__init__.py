"""What users run: the set-up plan, the pipeline, auto, the command line, the bench, the error metric, chains."""
