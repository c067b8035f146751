//! Reading and writing images: HDR/EXR environment maps in, float EXR and tone-mapped PNG out.
