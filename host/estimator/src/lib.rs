//! Shear, force, contact and edge estimation.
