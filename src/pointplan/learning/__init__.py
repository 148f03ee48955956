"""Training: SAC + HER, hindsight replay, behavioural cloning, DAgger, the training loop."""
