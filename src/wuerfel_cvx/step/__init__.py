"""One time step: the model, the contact search and the driver that steps it."""
