//! Colour names, as X11's rgb.txt spells them (the subset worlds use, plus greys).

use troupe_msgs::Color;

const NAMED: &[(&str, [u8; 3])] = &[
    ("black", [0, 0, 0]),
    ("white", [255, 255, 255]),
    ("red", [255, 0, 0]),
    ("green", [0, 255, 0]),
    ("blue", [0, 0, 255]),
    ("yellow", [255, 255, 0]),
    ("cyan", [0, 255, 255]),
    ("magenta", [255, 0, 255]),
    ("orange", [255, 165, 0]),
    ("purple", [160, 32, 240]),
    ("gray", [190, 190, 190]),
    ("grey", [190, 190, 190]),
    ("brown", [165, 42, 42]),
    ("pink", [255, 192, 203]),
    ("navy", [0, 0, 128]),
    ("NavyBlue", [0, 0, 128]),
    ("navy blue", [0, 0, 128]),
    ("LightBlue", [173, 216, 230]),
    ("light blue", [173, 216, 230]),
    ("DarkBlue", [0, 0, 139]),
    ("dark blue", [0, 0, 139]),
    ("DarkGreen", [0, 100, 0]),
    ("dark green", [0, 100, 0]),
    ("LightGreen", [144, 238, 144]),
    ("light green", [144, 238, 144]),
    ("DarkRed", [139, 0, 0]),
    ("dark red", [139, 0, 0]),
    ("DarkCyan", [0, 139, 139]),
    ("dark cyan", [0, 139, 139]),
    ("DarkMagenta", [139, 0, 139]),
    ("dark magenta", [139, 0, 139]),
    ("LightGray", [211, 211, 211]),
    ("LightGrey", [211, 211, 211]),
    ("light gray", [211, 211, 211]),
    ("light grey", [211, 211, 211]),
    ("DarkGray", [169, 169, 169]),
    ("DarkGrey", [169, 169, 169]),
    ("dark gray", [169, 169, 169]),
    ("dark grey", [169, 169, 169]),
    ("gold", [255, 215, 0]),
    ("violet", [238, 130, 238]),
    ("maroon", [176, 48, 96]),
    ("tan", [210, 180, 140]),
    ("beige", [245, 245, 220]),
    ("khaki", [240, 230, 140]),
    ("salmon", [250, 128, 114]),
    ("turquoise", [64, 224, 208]),
    ("SkyBlue", [135, 206, 235]),
    ("sky blue", [135, 206, 235]),
    ("ForestGreen", [34, 139, 34]),
    ("forest green", [34, 139, 34]),
    ("SteelBlue", [70, 130, 180]),
    ("steel blue", [70, 130, 180]),
    ("RoyalBlue", [65, 105, 225]),
    ("royal blue", [65, 105, 225]),
    ("chocolate", [210, 105, 30]),
    ("firebrick", [178, 34, 34]),
    ("coral", [255, 127, 80]),
    ("tomato", [255, 99, 71]),
    ("DarkOrange", [255, 140, 0]),
    ("dark orange", [255, 140, 0]),
    ("SeaGreen", [46, 139, 87]),
    ("sea green", [46, 139, 87]),
    ("LimeGreen", [50, 205, 50]),
    ("lime green", [50, 205, 50]),
    ("orchid", [218, 112, 214]),
    ("plum", [221, 160, 221]),
    ("wheat", [245, 222, 179]),
    ("ivory", [255, 255, 240]),
];

/// SplitMix64's step between states.
const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's output function: a state to well-mixed bits.
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform draw in [0, 1), a fixed function of `keys` (SplitMix64's
/// mixing, as `color "random"` uses it): the simulator's random numbers,
/// the same on every run.
pub(crate) fn unit_draw<const N: usize>(keys: [u64; N]) -> f64 {
    let z = keys.iter().fold(0x243F_6A88_85A3_08D3u64, |z, &k| {
        mix64((z ^ k).wrapping_add(GOLDEN))
    });
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// The `n`-th colour of `color "random"`: opaque, its channels spread over
/// [0, 1) by a fixed sequence (SplitMix64), so a world looks the same on
/// every load.
pub fn random(n: u64) -> Color {
    let z = mix64(n.wrapping_add(1).wrapping_mul(GOLDEN));
    let channel = |shift: u32| f32::from(((z >> shift) & 0xff) as u8) / 255.0;
    Color {
        r: channel(0),
        g: channel(8),
        b: channel(16),
        a: 1.0,
    }
}

/// The colour called `name`: an X11 name (`"gray30"`, `"NavyBlue"`), or
/// `None` when unknown (Stage then uses red).
pub fn lookup(name: &str) -> Option<Color> {
    let rgb = |[r, g, b]: [u8; 3]| Color {
        r: f32::from(r) / 255.0,
        g: f32::from(g) / 255.0,
        b: f32::from(b) / 255.0,
        a: 1.0,
    };
    // grayN / greyN, N in 0..=100, as rgb.txt rounds them.
    for prefix in ["gray", "grey"] {
        if let Some(n) = name
            .strip_prefix(prefix)
            .and_then(|n| n.parse::<u32>().ok())
        {
            if n <= 100 {
                // rgb.txt rounds halves up except at 50 and 90.
                let v = match n {
                    50 => 127,
                    90 => 229,
                    _ => ((n as f64) * 255.0 / 100.0).round() as u8,
                };
                return Some(rgb([v, v, v]));
            }
        }
    }
    NAMED.iter().find(|(n, _)| *n == name).map(|(_, c)| rgb(*c))
}

/// Stage's colour for an unknown name.
pub const RED: Color = Color {
    r: 1.0,
    g: 0.0,
    b: 0.0,
    a: 1.0,
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn x11_names_and_greys() {
        assert_eq!(lookup("gray50").unwrap().r, 127.0 / 255.0);
        assert_eq!(lookup("gray30").unwrap().g, 77.0 / 255.0);
        assert_eq!(lookup("gray").unwrap().r, 190.0 / 255.0);
        assert_eq!(lookup("purple").unwrap().g, 32.0 / 255.0);
        assert!(lookup("NavyBlue").is_some() && lookup("LightBlue").is_some());
        // fasr2.world's zones.
        assert_eq!(lookup("DarkCyan").unwrap().b, 139.0 / 255.0);
        assert_eq!(lookup("DarkMagenta").unwrap().r, 139.0 / 255.0);
        assert!(lookup("no such colour").is_none());
    }
}
