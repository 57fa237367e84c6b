//! Synthetic NUSense sensor.
