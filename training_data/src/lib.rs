//! Synthetic drone videos of signs in warehouse-like scenes, with exact boxes, and
//! import / export of real datasets (COCO JSON, Pascal VOC XML, GTSDB-style CSV).
#![deny(missing_docs)]
