//! Readers for particle dumps.
