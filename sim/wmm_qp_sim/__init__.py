"""The simulated wheeled mobile manipulator: a pure model and its Zenoh adapter."""
