//! The names rig logs give their channels (WITS and WITSML mnemonics, service companies' and
//! memory tools' exports), by the role bitrock reads them in. A column's name is split into
//! words at `_`, `-`, `.`, spaces and brackets (a bracketed unit aside), and a word is compared
//! with the table, case aside: `RPM_DH`, `DH RPM [rpm]` and `TOB (kN.m)` are the bit's speed and
//! torque. The table is in docs/records.md; a column that it misses is named with the
//! command's column flag, or in a column map file ([`ColumnMap`]).

/// A role a record's column can play: the bit's speed, torque or weight, or the clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Speed,
    Torque,
    Wob,
    Time,
}

/// Words that name a channel of the bit itself, unambiguously (downhole tools' and WITS's
/// downhole mnemonics, or a word with a downhole mark).
const BIT_WORDS: &[(Role, &[&str])] = &[
    (Role::Speed, &["drpm", "dhrpm", "rpmdh", "bitrpm", "rpmb", "brpm"]),
    (Role::Torque, &["tob", "dtor", "dtq", "dhtq", "tqdh", "dhtor", "tqb"]),
    (Role::Wob, &["wob", "dwob", "dhwob", "wobdh", "woba", "swob"]),
    (Role::Time, &["tim", "dtim", "timestamp", "datetime"]),
];

/// Words that name a speed or torque without saying where it was measured: read as the bit's
/// where nothing else is, and said ([`ambiguous`]).
const BARE_WORDS: &[(Role, &[&str])] = &[(Role::Speed, &["rpm"]), (Role::Torque, &["tq", "trq"])];

/// Words that name a depth along the hole, the bit's first (`DBTM`, WITS item 0108) and the
/// hole's after (`DMEA`, 0110: the bit's while it drills on bottom): [`depth_rank`].
const DEPTH_WORDS: [&[&str]; 2] = [&["dbtm", "bitdepth", "bdep"], &["depth", "dept", "dmea", "hdep"]];

/// How a column's name names a depth: 0 the bit's (a bit-depth mnemonic, or a depth word beside
/// `bit`), 1 another depth (the hole's, or a depth that does not say), `None` no depth.
pub fn depth_rank(name: &str) -> Option<usize> {
    let words = words(name);
    let has = |table: &[&str]| words.iter().any(|w| table.contains(&w.as_str()));
    if has(DEPTH_WORDS[0]) || (has(DEPTH_WORDS[1]) && words.iter().any(|w| w == "bit")) {
        Some(0)
    } else if has(DEPTH_WORDS[1]) {
        Some(1)
    } else {
        None
    }
}

/// Words that mark a channel measured downhole.
const DOWNHOLE_WORDS: &[&str] = &["dh", "downhole", "bit", "mwd", "memory"];

/// Words that mark a channel measured at the surface (top-drive speed, surface torque, hook
/// load): never read as the bit's unless named.
const SURFACE_WORDS: &[&str] = &[
    "surface", "surf", "rotary", "topdrive", "td", "tds", "tdrpm", "tdtq", "tqa", "rpma", "srpm", "stor", "stq",
];

/// A rig's channel names by role, from a column map file (TOML), for records whose names the
/// table misses: `speed`, `torque`, `wob` and `time` name the columns, `speed_unit`,
/// `torque_unit` and `wob_unit` their units as the rig writes them (`rpm`, `kN.m`, `kft.lbf`,
/// `klbf`). A column or unit given by its own setting beside the map wins.
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnMap {
    speed: Option<String>,
    torque: Option<String>,
    wob: Option<String>,
    time: Option<String>,
    speed_unit: Option<String>,
    torque_unit: Option<String>,
    wob_unit: Option<String>,
}

impl ColumnMap {
    /// `opts` with the map at `opts.column_map` filling the columns and units it leaves open;
    /// a unit the map names that bitrock does not read is refused naming the file and the key.
    pub fn apply(opts: &super::DataOptions) -> crate::error::Result<super::DataOptions> {
        use crate::units::{ForceUnit, SpeedUnit, TorqueUnit};
        let Some(path) = &opts.column_map else {
            return Ok(opts.clone());
        };
        let map: ColumnMap = crate::files::read_toml(path, "a column map")?;
        let unit = |key: &str, text: &Option<String>, parse: &dyn Fn(&str) -> bool| match text {
            Some(t) if !parse(t) => Err(crate::error::Error::Format {
                path: path.clone(),
                line: None,
                message: format!("{key} = \"{t}\": a unit bitrock does not read (docs/records.md lists them)"),
            }),
            _ => Ok(()),
        };
        unit("speed_unit", &map.speed_unit, &|t| SpeedUnit::from_symbol(t).is_some())?;
        unit("torque_unit", &map.torque_unit, &|t| {
            TorqueUnit::from_symbol(t).is_some()
        })?;
        unit("wob_unit", &map.wob_unit, &|t| ForceUnit::from_symbol(t).is_some())?;
        let or = |given: &Option<String>, mapped: Option<String>| given.clone().or(mapped);
        Ok(super::DataOptions {
            speed_column: or(&opts.speed_column, map.speed),
            torque_column: or(&opts.torque_column, map.torque),
            wob_column: or(&opts.wob_column, map.wob),
            time_column: or(&opts.time_column, map.time),
            speed_unit: opts
                .speed_unit
                .or(map.speed_unit.as_deref().and_then(SpeedUnit::from_symbol)),
            torque_unit: opts
                .torque_unit
                .or(map.torque_unit.as_deref().and_then(TorqueUnit::from_symbol)),
            wob_unit: opts
                .wob_unit
                .or(map.wob_unit.as_deref().and_then(ForceUnit::from_symbol)),
            column_map: None,
            ..opts.clone()
        })
    }
}

/// The words of a column's name, lower case, a bracketed unit left out.
fn words(name: &str) -> Vec<String> {
    let name = match crate::units::bracketed(name) {
        Some(unit) => &name.trim_end()[..name.trim_end().len() - unit.len() - 2],
        None => name,
    };
    name.split(['_', '-', '.', ' ', '(', ')', '[', ']', '/'])
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_lowercase)
        .collect()
}

/// True for a column whose name marks it as measured at the surface (its name holds
/// `surface`, `top_drive` or `rotary`, or a surface mnemonic as a word: `TQA`, `RPMA`,
/// `SRPM`, `TD_RPM`).
pub fn is_surface(name: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    ["surface", "top_drive", "rotary"]
        .iter()
        .any(|mark| lower.contains(mark))
        || words(name).iter().any(|w| SURFACE_WORDS.contains(&w.as_str()))
}

/// Words that name a surface channel's speed or torque (`RPMA`, `TD_RPM`, `TQA`, `STOR`), beside
/// a surface mark or as a surface mnemonic themselves ([`surface_role`]).
const SURFACE_SPEED_WORDS: &[&str] = &["rpma", "srpm", "tdrpm", "rpm", "speed"];
const SURFACE_TORQUE_WORDS: &[&str] = &["tqa", "stor", "stq", "tdtq", "tq", "trq", "torque"];

/// The role a surface channel's name gives it (the top drive's speed or the surface torque),
/// where the name marks it as measured at the surface ([`is_surface`]); `None` otherwise.
pub fn surface_role(name: &str) -> Option<Role> {
    if !is_surface(name) {
        return None;
    }
    let words = words(name);
    let has = |table: &[&str]| words.iter().any(|w| table.contains(&w.as_str()));
    if has(SURFACE_TORQUE_WORDS) {
        Some(Role::Torque)
    } else if has(SURFACE_SPEED_WORDS) {
        Some(Role::Speed)
    } else {
        None
    }
}

/// The role a column's name gives it by the mnemonics' table, if any. A speed that names an
/// extreme (an MWD tool's downhole minimum or maximum, [`downhole_extreme`]) is no speed of
/// the bit's: its samples are a window's extremes, not the bit's speed at the sample.
pub fn role(name: &str) -> Option<Role> {
    let words = words(name);
    let has = |table: &[(Role, &[&str])]| {
        table
            .iter()
            .find(|(_, names)| words.iter().any(|w| names.contains(&w.as_str())))
            .map(|(role, _)| *role)
    };
    has(BIT_WORDS)
        .or_else(|| has(BARE_WORDS))
        .filter(|&role| role != Role::Speed || downhole_extreme(name).is_none())
}

/// Which extreme of the bit speed over a window a column holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Extreme {
    Least,
    Greatest,
}

const LEAST_WORDS: &[&str] = &["min", "minimum"];
const GREATEST_WORDS: &[&str] = &["max", "maximum"];

/// The extreme a column's name says it holds where it names a speed beside `min` or `max`
/// (`downhole_min_rpm`, `DRPM_MIN`, `bit speed max [rpm]`): an MWD tool's downhole minimum or
/// maximum bit speed. A surface channel's name is for the caller to set aside.
pub fn downhole_extreme(name: &str) -> Option<Extreme> {
    let words = words(name);
    let has = |table: &[&str]| words.iter().any(|w| table.contains(&w.as_str()));
    let names_speed = words.iter().any(|w| {
        w == "speed"
            || BIT_WORDS
                .iter()
                .chain(BARE_WORDS)
                .any(|(role, names)| *role == Role::Speed && names.contains(&w.as_str()))
    });
    if !names_speed {
        return None;
    }
    match (has(LEAST_WORDS), has(GREATEST_WORDS)) {
        (true, false) => Some(Extreme::Least),
        (false, true) => Some(Extreme::Greatest),
        _ => None,
    }
}

/// Whether a column read by the mnemonics' table is named by a word rig logs also use for the
/// surface channel (`RPM`, `TQ`) with no downhole mark beside it.
pub fn ambiguous(name: &str) -> bool {
    let words = words(name);
    let bare = BARE_WORDS
        .iter()
        .any(|(_, names)| words.iter().any(|w| names.contains(&w.as_str())));
    let bit = BIT_WORDS
        .iter()
        .any(|(_, names)| words.iter().any(|w| names.contains(&w.as_str())));
    bare && !bit && !words.iter().any(|w| DOWNHOLE_WORDS.contains(&w.as_str()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rig_mnemonics_name_their_roles() {
        assert_eq!(role("RPM_DH"), Some(Role::Speed));
        assert_eq!(role("DH RPM [rpm]"), Some(Role::Speed));
        assert_eq!(role("DRPM"), Some(Role::Speed));
        assert_eq!(role("TQ_kNm"), Some(Role::Torque));
        assert_eq!(role("TOB (kN.m)"), Some(Role::Torque));
        assert_eq!(role("DWOB"), Some(Role::Wob));
        assert_eq!(role("DTIM"), Some(Role::Time));
        assert_eq!(role("depth_m"), None);
        assert_eq!(surface_role("RPMA [rpm]"), Some(Role::Speed));
        assert_eq!(surface_role("TD_RPM"), Some(Role::Speed));
        assert_eq!(surface_role("TQA (kft.lbf)"), Some(Role::Torque));
        assert_eq!(surface_role("STOR [kN.m]"), Some(Role::Torque));
        assert_eq!(surface_role("top_drive_rpm"), Some(Role::Speed));
        assert_eq!(surface_role("DRPM"), None, "the bit's");
        assert_eq!(depth_rank("DBTM [m]"), Some(0));
        assert_eq!(depth_rank("bit_depth_ft"), Some(0));
        assert_eq!(depth_rank("hole_depth_m"), Some(1));
        assert_eq!(depth_rank("DMEA [ft]"), Some(1));
        assert_eq!(depth_rank("bit_speed_rpm"), None);
        // A bracketed unit is no word of the name.
        assert_eq!(role("depth [rpm]"), None);
    }

    #[test]
    fn surface_mnemonics_and_marks_are_the_surface() {
        for name in [
            "TQA",
            "RPMA",
            "SRPM",
            "TD_RPM",
            "Surf RPM",
            "top_drive_rpm",
            "surface_torque_knm",
        ] {
            assert!(is_surface(name), "{name}");
        }
        for name in ["RPM_DH", "TOB", "bit_speed_rpm", "TQ_kNm", "stored_torque_knm"] {
            assert!(!is_surface(name), "{name}");
        }
    }

    #[test]
    fn bare_speed_and_torque_words_are_said_unless_marked_downhole() {
        assert!(ambiguous("TQ_kNm"));
        assert!(ambiguous("RPM"));
        assert!(!ambiguous("RPM_DH"));
        assert!(!ambiguous("TOB"));
        assert!(!ambiguous("bit_speed_rpm"));
    }
}
