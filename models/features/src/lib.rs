//! The feature-based detector family of the paper: EdgeBoxes proposals, HoG features
//! and a linear SVM per class, whose variants are parameter tuples
//! ⟨proposals, block size, cell size, histogram bins⟩.
#![deny(missing_docs)]
