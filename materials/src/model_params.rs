//! What a hair model's parameters tell the rest of tress beyond building the model: the pigment
//! and the roughness, which per-strand variation ([`crate::strand_variation`]) changes.

use crate::pigment::Pigment;

/// Implemented by every model's `Params`, next to the model. The registry ([`crate::HairModel`])
/// reaches a model's pigment and roughness only through it, so registering a model needs no
/// match arm anywhere else.
pub trait ModelParams {
    /// The pigment, with the azimuthal roughness β_n at which it converts a
    /// [`Pigment::Color`] (Chiang's fit); `None` for a model without one.
    fn pigment(&self) -> Option<(&Pigment, f32)>;

    /// The pigment to change in place; `None` exactly when [`Self::pigment`] is `None`.
    fn pigment_mut(&mut self) -> Option<&mut Pigment>;

    /// Multiplies the model's roughness by `scale` (positive), clamped to its valid range; a
    /// model without roughness is left as it is.
    fn scale_roughness(&mut self, scale: f32);
}
