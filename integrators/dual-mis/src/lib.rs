//! Dual scattering with MIS of light and BCSDF sampling; lands with the dual-scattering tables.
