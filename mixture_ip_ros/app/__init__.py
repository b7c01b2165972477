"""Applications: the command line, training, evaluation, the closed loop and the demo."""
