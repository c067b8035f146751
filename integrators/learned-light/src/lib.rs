//! What the integrators that learn the light in a scene from the film's own paths share
//! (`radiance-cache`, `guided`): a lattice of cells at several sizes over the scene's bounds
//! ([`Lattice`]), the mean radiance leaving its cells ([`RadianceCache`]) and training paths traced through the film's pixels so that what is learned
//! depends only on the scene, the film's size and seed, and the training path indices, never on
//! threads ([`train`]).

#![warn(missing_docs)]

mod blocks;
mod lattice;
mod radiance;
mod settings;
#[cfg(test)]
mod test_util;
mod training;

pub use blocks::{block_of, block_segments, block_start, blocks_of};
pub use lattice::Lattice;
pub use radiance::{RadianceCache, Records};
pub use settings::{check_ranges, BlockLearning, LastFilm, OutOfRange, RangeCheck};
pub use training::{train, FilmKey};
