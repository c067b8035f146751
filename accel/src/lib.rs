//! tress-accel: Embree geometry for tress.
