//! Dual scattering with uniform light-direction sampling (Zinke et al. 2008); lands with the dual-scattering tables.
