"""Networks and the inference policy: encoders, actor and critics, checkpoint I/O."""
