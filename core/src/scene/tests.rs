//! Robustness tests of the scene readers on small synthetic files.
