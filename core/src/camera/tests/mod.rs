//! Unit tests of the camera readers, writers and generators.
