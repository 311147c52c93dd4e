//! Saving and loading a compiled [`HybridModel`]: one versioned binary file with a checksum.
