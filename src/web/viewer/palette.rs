//! The categorical palette shared by the 3D view, the legend and the tree
//! diagram (exported so the page uses exactly the same colours).

/// sRGB colours, distinct at a glance; grey is kept for "no label".
pub const PALETTE: [[u8; 3]; 20] = [
    [78, 121, 167],
    [242, 142, 43],
    [89, 161, 79],
    [225, 87, 89],
    [118, 183, 178],
    [237, 201, 72],
    [176, 122, 161],
    [156, 117, 95],
    [255, 157, 167],
    [23, 190, 207],
    [44, 62, 140],
    [255, 190, 125],
    [140, 209, 125],
    [182, 153, 45],
    [73, 152, 148],
    [160, 203, 232],
    [211, 114, 149],
    [250, 191, 210],
    [212, 166, 200],
    [110, 64, 40],
];

/// Colour of points without a label (`u32::MAX`) and of the "plain" mode.
pub const UNLABELED: [u8; 3] = [150, 150, 150];

/// Joint axes and the selected joint.
pub const AXIS_COLOR: [u8; 3] = [230, 0, 126];
pub const AXIS_HIGHLIGHT: [u8; 3] = [255, 200, 0];

/// Background of the view (light neutral), sRGB.
pub const BACKGROUND: [u8; 3] = [242, 242, 240];

/// Colour of label `i`; the palette repeats after 20 labels.
pub fn color(i: u32) -> [u8; 3] {
    if i == u32::MAX {
        UNLABELED
    } else {
        PALETTE[(i as usize) % PALETTE.len()]
    }
}

/// Pack an sRGB colour with alpha 255 as the little-endian RGBA8 the shaders read.
pub fn pack(c: [u8; 3]) -> u32 {
    u32::from_le_bytes([c[0], c[1], c[2], 255])
}
