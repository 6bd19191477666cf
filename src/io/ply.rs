//! PLY reading (ascii, binary little/big endian, any vertex layout, meshes sampled by
//! area) and writing (segmented output with a `part` property).
