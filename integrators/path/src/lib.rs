//! Unidirectional path tracer.
