//! Plots of the product (feature `plots`, on in the `cdvol` binary):
//! [`histogram`], `cdvol histogram`'s plot of a packed file's value
//! histogram, and [`font`], the one embedded font every plot and the
//! demo's contact sheet draw text with.

pub mod font;
pub mod histogram;
