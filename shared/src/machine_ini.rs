//! A machine file from a LinuxCNC INI file (`cnc machine --from-ini machine.ini`): the
//! limits a LinuxCNC user has already measured and tuned, in our units, each key with a
//! comment naming the INI line it came from.
//!
//! What is read (units from `[TRAJ]LINEAR_UNITS`: `mm`/`metric`, `inch`/`in`/`imperial`,
//! or a number of machine units per mm; velocities per second as the INI has them):
//!
//! | INI | machine file |
//! |---|---|
//! | `[TRAJ]MAX_LINEAR_VELOCITY` (2.7's `MAX_VELOCITY`) | `max_feed_mm_per_min`, `rapid_mm_per_min` (LinuxCNC caps feeds and rapids by it) |
//! | `[TRAJ]MAX_LINEAR_ACCELERATION` (2.7's `MAX_ACCELERATION`) | `path_acc_mm_per_s2` |
//! | `[AXIS_X/Y/Z]` and their joints' `MAX_VELOCITY`, `MAX_ACCELERATION` | `axes.*.max_vel_mm_per_min`, `max_acc_mm_per_s2`: the tighter of the axis and its joints |
//! | `[AXIS_X/Y/Z]` and their joints' `MIN_LIMIT`, `MAX_LIMIT` | `axes.*.min_mm`, `max_mm`: the tighter |
//! | `[JOINT_n]FERROR` | `max_following_error_mm`: the least of the joints' |
//! | `[EMCMOT]SERVO_PERIOD` (ns) | `min_period_us` |
//! | `[RS274NGC]RS274NGC_STARTUP_CODE`'s `G64 P`, `G61` | `blend_tolerance_mm` (a bare `G64` keeps our default: LinuxCNC's has no bound) |
//!
//! Joints belong to axes as `trivkins` says: its `coordinates=` parameter on
//! `[KINS]KINEMATICS`, else `[TRAJ]COORDINATES`, joint `n` the `n`-th letter (a letter
//! twice is a gantry: both joints limit the axis). Other kinematics leave joints out
//! (their joint limits are not axis limits), with a warning.
//!
//! LinuxCNC 2.9 has no jerk limit: the jerk keys get the machine's acceleration reached
//! within one servo period, which limits nothing LinuxCNC would not do. Every other key
//! keeps our default, and so does the servo model: an INI holds the drive's tuning in
//! HAL files, not in a form this can read.
//!
//! Each key of `[TRAJ]`, `[AXIS_*]`, `[JOINT_*]`, `[KINS]` and `[EMCMOT]` that has no
//! counterpart is a warning naming its line (`MIN_FERROR`: our following-error limit
//! is one value at every speed); every other section is one warning (the user
//! interface, HAL, the tool table: nothing of a machine's limits).

use crate::machine::Machine;

/// One `KEY = VALUE` of the INI file.
#[derive(Debug, Clone)]
struct Entry {
    section: String,
    key: String,
    value: String,
    /// `file:line` where it was read.
    line: String,
}

/// A machine file made from an INI file.
#[derive(Debug, Clone)]
pub struct FromIni {
    pub machine: Machine,
    /// The machine file's text: every key with its meaning, and where it came from.
    pub toml: String,
    /// INI keys and sections with no counterpart, each naming its line.
    pub warnings: Vec<String>,
}

/// The sections whose keys are read or warned about one by one.
const MOTION_SECTIONS: [&str; 3] = ["TRAJ", "KINS", "EMCMOT"];

/// A value this large is LinuxCNC's "no limit" (its defaults are ±1e99).
const UNLIMITED: f64 = 1e30;

/// Half the travel (mm) of an axis the INI's machine does not have.
const ABSENT_TRAVEL_MM: f64 = 0.001;

/// Most levels of `#INCLUDE` within one another.
const MAX_INCLUDE_DEPTH: usize = 8;

/// The entries of `text` (read from `file`), the files it `#INCLUDE`s read by `include`
/// in their place, each entry under the section it comes after.
fn parse(
    text: &str,
    file: &str,
    include: &dyn Fn(&str) -> Result<String, String>,
    depth: usize,
    section: &mut String,
    out: &mut Vec<Entry>,
) -> Result<(), String> {
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if let Some(name) = line.strip_prefix("#INCLUDE") {
            let name = name.trim();
            if depth >= MAX_INCLUDE_DEPTH {
                return Err(format!(
                    "{file}:{}: #INCLUDE {name}: more than {MAX_INCLUDE_DEPTH} deep (a file that includes itself?)",
                    i + 1
                ));
            }
            // Beside the file that includes it (LinuxCNC master; 2.9 does not nest).
            let path = match std::path::Path::new(file).parent() {
                Some(d) if !d.as_os_str().is_empty() => d.join(name).display().to_string(),
                _ => name.to_string(),
            };
            let inner = include(&path).map_err(|e| format!("{file}:{}: #INCLUDE {e}", i + 1))?;
            parse(&inner, &path, include, depth + 1, section, out)?;
            continue;
        }
        if line.is_empty() || line.starts_with('#') || line.starts_with(';') {
            continue;
        }
        // (`[AXIS_Z]   ; the quill`: what follows the bracket is a comment.)
        if let Some((name, _)) = line.strip_prefix('[').and_then(|l| l.split_once(']')) {
            *section = name.trim().to_string();
            continue;
        }
        if let Some((k, v)) = line.split_once('=') {
            out.push(Entry {
                section: section.clone(),
                key: k.trim().to_string(),
                value: v.trim().to_string(),
                line: format!("{file}:{}", i + 1),
            });
        }
    }
    Ok(())
}

/// What is being made: the entries, which of them were used, the notes per key.
struct Reading {
    entries: Vec<Entry>,
    used: Vec<bool>,
    /// Machine file key (`axes.x.max_mm`) → where it came from.
    notes: Vec<(String, String)>,
}

impl Reading {
    /// The first `KEY` of `[SECTION]` (LinuxCNC reads the first), marked used.
    fn get(&mut self, section: &str, key: &str) -> Option<(String, String)> {
        let i = self
            .entries
            .iter()
            .position(|e| e.section == section && e.key == key)?;
        self.used[i] = true;
        Some((self.entries[i].line.clone(), self.entries[i].value.clone()))
    }

    /// A number at `[SECTION]KEY`, if given: with its line.
    fn number(&mut self, section: &str, key: &str) -> Result<Option<(f64, String)>, String> {
        let Some((line, value)) = self.get(section, key) else {
            return Ok(None);
        };
        match value.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some((v, line))),
            _ => Err(format!("{line}: [{section}]{key} = {value}: not a number")),
        }
    }

    fn note(&mut self, key: &str, text: String) {
        self.notes.push((key.to_string(), text));
    }
}

/// The machine file for the LinuxCNC INI `text` (read from `file`, for messages);
/// `include` reads the files its `#INCLUDE` lines name.
pub fn from_ini(
    text: &str,
    file: &str,
    include: &dyn Fn(&str) -> Result<String, String>,
) -> Result<FromIni, String> {
    let mut entries = Vec::new();
    parse(text, file, include, 0, &mut String::new(), &mut entries)?;
    if entries.is_empty() {
        return Err(format!(
            "{file}: no `KEY = VALUE` lines: not a LinuxCNC INI file"
        ));
    }
    let mut r = Reading {
        used: vec![false; entries.len()],
        entries,
        notes: Vec::new(),
    };
    let mut m = Machine::default();
    let mut warnings = Vec::new();

    // Units.
    let mut unit_name = "mm";
    let (unit, unit_from) = match r.get("TRAJ", "LINEAR_UNITS") {
        None => {
            warnings.push(format!(
                "{file}: no [TRAJ]LINEAR_UNITS: millimetres assumed"
            ));
            (1.0, "millimetres (no [TRAJ]LINEAR_UNITS)".to_string())
        }
        Some((line, v)) => {
            let unit = match v.to_ascii_lowercase().as_str() {
                "mm" | "metric" => 1.0,
                "in" | "inch" | "imperial" => {
                    unit_name = "inch";
                    25.4
                }
                other => match other.parse::<f64>() {
                    Ok(per_mm) if per_mm > 0.0 && per_mm.is_finite() => {
                        unit_name = "units";
                        1.0 / per_mm
                    }
                    _ => {
                        return Err(format!(
                            "{line}: [TRAJ]LINEAR_UNITS = {v}: expected mm, inch or a number of units per mm"
                        ))
                    }
                },
            };
            (unit, format!("{v} ({line})"))
        }
    };
    let from = |section: &str, key: &str, line: &str, value: f64| {
        format!("from {line} [{section}]{key} = {value}")
    };

    // The servo period.
    let mut period_s = 0.001;
    if let Some((ns, line)) = r.number("EMCMOT", "SERVO_PERIOD")? {
        if ns < 1000.0 {
            return Err(format!(
                "{line}: [EMCMOT]SERVO_PERIOD = {ns}: a period in ns of at least 1 µs"
            ));
        }
        period_s = ns * 1e-9;
        m.min_period_us = (ns / 1000.0).round() as u64;
        m.max_period_us = m.max_period_us.max(m.min_period_us);
        r.note(
            "min_period_us",
            format!(
                "{} (LinuxCNC's servo period: the shortest this machine is known to run)",
                from("EMCMOT", "SERVO_PERIOD", &line, ns)
            ),
        );
    }
    let jerk_note = format!(
        "LinuxCNC 2.9 has no jerk limit: the acceleration reached in one servo period ({} µs)",
        (period_s * 1e6).round()
    );

    // The path.
    let traj_vel = match r.number("TRAJ", "MAX_LINEAR_VELOCITY")? {
        Some(v) => Some((v, "MAX_LINEAR_VELOCITY")),
        None => r
            .number("TRAJ", "MAX_VELOCITY")?
            .map(|v| (v, "MAX_VELOCITY")),
    };
    if let Some(((v, line), key)) = traj_vel {
        let mm_min = tidy(v * unit * 60.0);
        m.max_feed_mm_per_min = mm_min;
        m.rapid_mm_per_min = mm_min;
        let n = from("TRAJ", key, &line, v);
        r.note("max_feed_mm_per_min", format!("{n} {unit_name}/s"));
        r.note(
            "rapid_mm_per_min",
            format!("{n} {unit_name}/s (rapids run at it)"),
        );
    }
    let traj_acc = match r.number("TRAJ", "MAX_LINEAR_ACCELERATION")? {
        Some(v) => Some((v, "MAX_LINEAR_ACCELERATION")),
        None => r
            .number("TRAJ", "MAX_ACCELERATION")?
            .map(|v| (v, "MAX_ACCELERATION")),
    };
    if let Some(((a, line), key)) = traj_acc {
        m.path_acc_mm_per_s2 = tidy(a * unit);
        r.note(
            "path_acc_mm_per_s2",
            format!("{} {unit_name}/s²", from("TRAJ", key, &line, a)),
        );
    }
    m.path_jerk_mm_per_s3 = tidy(m.path_acc_mm_per_s2 / period_s);
    r.note("path_jerk_mm_per_s3", jerk_note.clone());

    // Which joints drive which axis.
    let mut joints_of: [Vec<usize>; 3] = Default::default();
    let kins = r.get("KINS", "KINEMATICS");
    let coordinates = r.get("TRAJ", "COORDINATES");
    let trivial = kins
        .as_ref()
        .is_none_or(|(_, k)| k.split_whitespace().next() == Some("trivkins"));
    if trivial {
        let letters: String = kins
            .as_ref()
            .and_then(|(_, k)| {
                k.split_whitespace()
                    .find_map(|p| p.strip_prefix("coordinates="))
                    .map(str::to_string)
            })
            // trivkins without `coordinates=` maps joints to XYZABCUVW in order, whatever
            // [TRAJ]COORDINATES says; a file without [KINS] (before 2.8) has joints
            // as its coordinates.
            .or_else(|| kins.as_ref().map(|_| "XYZABCUVW".to_string()))
            .or_else(|| coordinates.as_ref().map(|(_, c)| c.clone()))
            .unwrap_or_else(|| "XYZ".to_string());
        let letters: Vec<char> = letters
            .chars()
            .filter(|c| c.is_ascii_alphabetic())
            .map(|c| c.to_ascii_uppercase())
            .collect();
        for (joint, c) in letters.iter().enumerate() {
            match "XYZ".find(*c) {
                Some(a) => joints_of[a].push(joint),
                None => warnings.push(format!(
                    "{file}: joint {joint} drives axis {c}: this machine has X, Y and Z only; [AXIS_{c}] and [JOINT_{joint}] are not read"
                )),
            }
        }
    } else if let Some((line, k)) = &kins {
        warnings.push(format!(
            "{line}: [KINS]KINEMATICS = {k}: not trivkins, so joints are not axes; only the [AXIS_*] limits are read"
        ));
    }

    // The axes.
    let mut ferror: Option<(f64, String)> = None;
    for (a, name) in ["X", "Y", "Z"].into_iter().enumerate() {
        let key = name.to_ascii_lowercase();
        let section = format!("AXIS_{name}");
        let mut sources: Vec<String> = vec![section.clone()];
        sources.extend(joints_of[a].iter().map(|j| format!("JOINT_{j}")));
        let axis = match a {
            0 => &mut m.axes.x,
            1 => &mut m.axes.y,
            _ => &mut m.axes.z,
        };
        // The tightest of the axis and its joints, and where it came from; a section
        // without the key counts with LinuxCNC's default for it (`emccfg.h`: 1 unit/s
        // and 1 unit/s² for axes and joints alike), where it has one.
        let tightest = |r: &mut Reading,
                        ini_key: &str,
                        lower: bool,
                        default: Option<f64>|
         -> Result<Option<(f64, String)>, String> {
            let mut best: Option<(f64, String)> = None;
            for s in &sources {
                let (v, n) = match (r.number(s, ini_key)?, default) {
                    // (1e99 is how LinuxCNC writes "no limit": this section sets none.)
                    (Some((v, _)), _) if v.abs() >= UNLIMITED => continue,
                    (Some((v, line)), _) => (v, from(s, ini_key, &line, v)),
                    (None, Some(d)) => (
                        d,
                        format!("[{s}]{ini_key} not given in {file}: LinuxCNC's default {d}"),
                    ),
                    (None, None) => continue,
                };
                let better = best
                    .as_ref()
                    .is_none_or(|(b, _)| if lower { v < *b } else { v > *b });
                if better {
                    best = Some((v, n));
                }
            }
            Ok(best)
        };
        if let Some((v, n)) = tightest(&mut r, "MAX_VELOCITY", true, Some(1.0))? {
            axis.max_vel_mm_per_min = tidy(v * unit * 60.0);
            r.note(
                &format!("axes.{key}.max_vel_mm_per_min"),
                format!("{n} {unit_name}/s"),
            );
        }
        if let Some((v, n)) = tightest(&mut r, "MAX_ACCELERATION", true, Some(1.0))? {
            axis.max_acc_mm_per_s2 = tidy(v * unit);
            r.note(
                &format!("axes.{key}.max_acc_mm_per_s2"),
                format!("{n} {unit_name}/s²"),
            );
            axis.max_jerk_mm_per_s3 = tidy(axis.max_acc_mm_per_s2 / period_s);
            r.note(&format!("axes.{key}.max_jerk_mm_per_s3"), jerk_note.clone());
        }
        if let Some((v, n)) = tightest(&mut r, "MIN_LIMIT", false, None)? {
            axis.min_mm = tidy(v * unit);
            r.note(&format!("axes.{key}.min_mm"), n);
        }
        if let Some((v, n)) = tightest(&mut r, "MAX_LIMIT", true, None)? {
            axis.max_mm = tidy(v * unit);
            r.note(&format!("axes.{key}.max_mm"), n);
        }
        // An axis the machine does not have (a lathe's Y): LinuxCNC refuses a program
        // that moves it; here its travel is held to a micrometre either side of the
        // start, so that `cnc check` refuses such a program too.
        if let Some((line, c)) = &coordinates {
            if !c.to_ascii_uppercase().contains(name) {
                axis.min_mm = -ABSENT_TRAVEL_MM;
                axis.max_mm = ABSENT_TRAVEL_MM;
                let n = format!(
                    "{name} is not in {line} [TRAJ]COORDINATES = {c}: travel held to ±{ABSENT_TRAVEL_MM} mm, so that a program moving {name} is refused"
                );
                r.note(&format!("axes.{key}.min_mm"), n.clone());
                r.note(&format!("axes.{key}.max_mm"), n);
            }
        }
        for j in &joints_of[a] {
            let s = format!("JOINT_{j}");
            // (LinuxCNC's default FERROR is 1 unit.)
            let (v, n) = match r.number(&s, "FERROR")? {
                Some((v, line)) => (v, from(&s, "FERROR", &line, v)),
                None => (
                    1.0,
                    format!("[{s}]FERROR not given in {file}: LinuxCNC's default 1"),
                ),
            };
            if ferror.as_ref().is_none_or(|(b, _)| v * unit < *b) {
                ferror = Some((tidy(v * unit), n));
            }
        }
    }
    if let Some((v, n)) = ferror {
        m.max_following_error_mm = v;
        r.note(
            "max_following_error_mm",
            format!("{n} (the least of the joints'; LinuxCNC's limit at full speed)"),
        );
    }
    // The path mode programs start in: LinuxCNC's bare `G64` keeps the best speed
    // however far from the path, which a tolerance with no bound is not; a `P` given
    // there, or `G61`, says what the machine's builder wants.
    if let Some((line, code)) = r.get("RS274NGC", "RS274NGC_STARTUP_CODE") {
        let at = format!("{line} [RS274NGC]RS274NGC_STARTUP_CODE = {code}");
        match startup_path_mode(&code) {
            Some(StartMode::Exact(g)) => {
                m.blend_tolerance_mm = 0.0;
                r.note(
                    "blend_tolerance_mm",
                    format!("from {at}: {g}, the exact path (a bare G64 too)"),
                );
            }
            Some(StartMode::Blend(Some(p))) if p > 0.0 => {
                m.blend_tolerance_mm = tidy(p * unit);
                r.note(
                    "blend_tolerance_mm",
                    format!("from {at}: G64 P{p} (a bare G64 too)"),
                );
            }
            Some(StartMode::Blend(_)) => r.note(
                "blend_tolerance_mm",
                format!(
                    "{at}: a bare G64, LinuxCNC's best speed however far from the path: \
                     bounded here by this control's default"
                ),
            ),
            None => {}
        }
    }
    m.check().map_err(|e| {
        // Where the value the check refuses came from.
        let whence = r
            .notes
            .iter()
            .find(|(k, _)| e.starts_with(k.as_str()))
            .map(|(_, n)| format!(" ({n})"))
            .unwrap_or_default();
        format!("{file}: the machine it describes is not one this control runs: {e}{whence}")
    })?;

    // What was not read.
    let mut other_sections: Vec<(String, String, usize)> = Vec::new();
    for (e, used) in r.entries.iter().zip(&r.used) {
        if *used {
            continue;
        }
        let motion = MOTION_SECTIONS.contains(&e.section.as_str())
            || e.section.starts_with("AXIS_")
            || e.section.starts_with("JOINT_");
        if motion {
            let why = match e.key.as_str() {
                "MIN_FERROR" => " (our following-error limit is one value at every speed)",
                "DEFAULT_LINEAR_VELOCITY" | "DEFAULT_VELOCITY" => " (a jog and MDI default)",
                _ => "",
            };
            warnings.push(format!(
                "{}: [{}]{} = {}: no counterpart, not read{why}",
                e.line, e.section, e.key, e.value
            ));
        } else {
            match other_sections.iter_mut().find(|s| s.0 == e.section) {
                Some(s) => s.2 += 1,
                None => other_sections.push((e.section.clone(), e.line.clone(), 1)),
            }
        }
    }
    for (s, line, n) in other_sections {
        warnings.push(format!(
            "{line}: [{s}]: {n} key{} about what is not a machine's limits here, not read",
            if n == 1 { "" } else { "s" }
        ));
    }

    let header = format!(
        "# cnc machine file made by `cnc machine --from-ini {file}`.\n# LinuxCNC units: {unit_from}, {unit} mm each; velocities there are per second.\n# Keys without a note keep this control's defaults (the servo model among them).\n"
    );
    let toml = m.documented_toml(&header, |key| {
        r.notes
            .iter()
            .filter(|(k, _)| k == key)
            .map(|(_, n)| n.clone())
            .collect()
    });
    Ok(FromIni {
        machine: m,
        toml,
        warnings,
    })
}

/// The path mode a startup code leaves in force (its last path-mode word).
#[derive(Debug, Clone, PartialEq)]
enum StartMode {
    /// `G61` or `G61.1`, as written.
    Exact(String),
    /// `G64`, with its `P` if one follows it.
    Blend(Option<f64>),
}

/// [`StartMode`] of a LinuxCNC startup code (`G17 G21 G64 P0.01 …`); `None` without a
/// path-mode word. Words may be written together (`G64P0.01`) or apart, in any case.
fn startup_path_mode(code: &str) -> Option<StartMode> {
    let code = code.to_ascii_uppercase();
    // The words: a letter and the number after it, spaces skipped.
    let mut words: Vec<(char, String)> = Vec::new();
    for c in code.chars().filter(|c| !c.is_whitespace()) {
        match words.last_mut() {
            Some((_, n)) if c.is_ascii_digit() || c == '.' || c == '-' || c == '+' => n.push(c),
            _ if c.is_ascii_alphabetic() => words.push((c, String::new())),
            _ => {}
        }
    }
    let mut mode = None;
    for (i, (letter, n)) in words.iter().enumerate() {
        if *letter != 'G' {
            continue;
        }
        match n.parse::<f64>() {
            Ok(g) if g == 61.0 || g == 61.1 => mode = Some(StartMode::Exact(format!("G{n}"))),
            Ok(64.0) => {
                let p = words
                    .get(i + 1)
                    .filter(|(l, _)| *l == 'P')
                    .and_then(|(_, v)| v.parse::<f64>().ok());
                mode = Some(StartMode::Blend(p));
            }
            _ => {}
        }
    }
    mode
}

/// `v` rounded to a nanometre's worth (nine decimals): an inch config's 30.48 mm/s is
/// 1828.8 mm/min in the file, not 1828.7999999999997.
fn tidy(v: f64) -> f64 {
    (v * 1e9).round() / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;

    fn none(name: &str) -> Result<String, String> {
        Err(format!("{name}: no such file"))
    }

    /// An inch machine with a gantry Y (two joints, one slower than the axis), a servo
    /// period of 0.5 ms and a key with no counterpart: every limit in mm, the tighter of
    /// axis and joints, jerk as the acceleration in one period, the file it writes read
    /// back to the same machine, and the key warned about at its line.
    #[test]
    fn an_inch_gantry_in_mm_with_the_tighter_limits() {
        let ini = "[EMCMOT]\nSERVO_PERIOD = 500000\n[TRAJ]\nLINEAR_UNITS = inch\nCOORDINATES = X Y Y Z\n\
                   MAX_LINEAR_VELOCITY = 2\nMAX_LINEAR_ACCELERATION = 10\nPOSITION_FILE = p.txt\n\
                   [KINS]\nKINEMATICS = trivkins coordinates=XYYZ kinstype=BOTH\nJOINTS = 4\n\
                   [AXIS_X]\nMAX_VELOCITY = 1.5\nMAX_ACCELERATION = 8\nMIN_LIMIT = -10\nMAX_LIMIT = 10\n\
                   [AXIS_Y]\nMAX_VELOCITY = 1.5\nMAX_ACCELERATION = 8\nMIN_LIMIT = -20\nMAX_LIMIT = 20\n\
                   [JOINT_1]\nMAX_VELOCITY = 1.2\nMAX_ACCELERATION = 9\nMIN_LIMIT = -19\nFERROR = 0.05\nMIN_FERROR = 0.01\n\
                   [JOINT_2]\nMAX_VELOCITY = 1.4\nMAX_LIMIT = 18\nFERROR = 0.04\nMAX_ACCELERATION = 9\n\
                   [JOINT_0]\nMAX_VELOCITY = 1.5\nMAX_ACCELERATION = 8\nFERROR = 0.05\n\
                   [DISPLAY]\nDISPLAY = axis\nCYCLE_TIME = 0.1\n";
        let f = from_ini(ini, "m.ini", &none).unwrap();
        let m = &f.machine;
        assert_eq!(m.max_feed_mm_per_min, 3048.0);
        assert_eq!(m.rapid_mm_per_min, 3048.0);
        assert_eq!(m.path_acc_mm_per_s2, 254.0);
        assert_eq!(m.path_jerk_mm_per_s3, 508_000.0);
        assert_eq!(m.min_period_us, 500);
        assert_eq!(m.axes.x.max_vel_mm_per_min, 2286.0);
        assert_eq!((m.axes.x.min_mm, m.axes.x.max_mm), (-254.0, 254.0));
        // Y: the slower joint's velocity, the axis's acceleration, each side's tighter
        // travel.
        assert_eq!(m.axes.y.max_vel_mm_per_min, 1828.8);
        assert_eq!(m.axes.y.max_acc_mm_per_s2, 203.2);
        assert_eq!((m.axes.y.min_mm, m.axes.y.max_mm), (-482.6, 457.2));
        assert_eq!(m.max_following_error_mm, 1.016);
        // Z (joint 3): nothing given, so LinuxCNC's defaults of 1 in/s and 1 in/s² for
        // the axis and its joint; its travel ours (LinuxCNC's is ±1e99: none).
        assert_eq!(m.axes.z.max_vel_mm_per_min, 1524.0);
        assert_eq!(m.axes.z.max_acc_mm_per_s2, 25.4);
        assert_eq!(m.axes.z.max_mm, Machine::default().axes.z.max_mm);
        assert_eq!(&Machine::from_toml(&f.toml).unwrap(), m);
        assert!(
            f.toml.contains(
                "# from m.ini:23 [JOINT_1]MAX_VELOCITY = 1.2 inch/s\nmax_vel_mm_per_min = 1828.8"
            ),
            "{}",
            f.toml
        );
        let warned = |s: &str| f.warnings.iter().any(|w| w.contains(s));
        assert!(warned("m.ini:8: [TRAJ]POSITION_FILE"), "{:?}", f.warnings);
        assert!(warned(
            "m.ini:27: [JOINT_1]MIN_FERROR = 0.01: no counterpart"
        ));
        assert!(warned("m.ini:38: [DISPLAY]: 2 keys"));
        assert!(!warned("MAX_VELOCITY") && !warned("COORDINATES"));
    }

    /// The review's cases: a key left out is LinuxCNC's default (1 unit/s, 1 unit/s²,
    /// FERROR 1), not ours, which is looser; plain `trivkins` maps joints to XYZABCUVW
    /// whatever COORDINATES says; an axis not in COORDINATES (a lathe's Y) is held to
    /// ±1 µm of travel; a section header may carry a comment; 1e99 is no limit; a value
    /// refused by the range check names its INI line.
    #[test]
    fn what_linuxcnc_would_do_with_what_is_left_out() {
        let lathe = "[TRAJ]\nLINEAR_UNITS = mm\nCOORDINATES = X Z\n[KINS]\nKINEMATICS = trivkins\n\
                     [AXIS_X]    ; the cross slide\nMAX_VELOCITY = 50\nMAX_ACCELERATION = 500\n\
                     [AXIS_Z]\nMAX_VELOCITY = 50\nMAX_ACCELERATION = 500\nMAX_LIMIT = 1e99\n\
                     [JOINT_0]\nMAX_VELOCITY = 60\nMAX_ACCELERATION = 600\nFERROR = 0.5\n\
                     [JOINT_2]\nMAX_VELOCITY = 20\nMAX_ACCELERATION = 100\nMAX_LIMIT = 5\nFERROR = 0.3\n";
        let m = from_ini(lathe, "l.ini", &none).unwrap().machine;
        assert_eq!(
            m.axes.x.max_vel_mm_per_min, 3000.0,
            "the axis, under its joint"
        );
        // Z is joint 2 (XYZABCUVW), not joint 1 (the second letter of X Z).
        assert_eq!(m.axes.z.max_vel_mm_per_min, 1200.0);
        assert_eq!(m.axes.z.max_mm, 5.0, "1e99 sets no limit; the joint's does");
        assert_eq!((m.axes.y.min_mm, m.axes.y.max_mm), (-0.001, 0.001));
        assert_eq!(m.max_following_error_mm, 0.3);
        let bare = "[TRAJ]\nLINEAR_UNITS = mm\n[AXIS_X]\nMIN_LIMIT = 0\nMAX_LIMIT = 200\n";
        let m = from_ini(bare, "b.ini", &none).unwrap().machine;
        assert_eq!(m.axes.x.max_vel_mm_per_min, 60.0);
        assert_eq!(m.axes.x.max_acc_mm_per_s2, 1.0);
        assert_eq!(m.max_following_error_mm, 1.0);
        let e = from_ini("[AXIS_X]\nMAX_ACCELERATION = 0.5\n", "a.ini", &none).unwrap_err();
        assert!(
            e.contains("(from a.ini:2 [AXIS_X]MAX_ACCELERATION = 0.5"),
            "{e}"
        );
    }

    /// `#INCLUDE` reads the named file in its place; what is wrong is named at its line.
    #[test]
    fn the_startup_code_s_path_mode_is_the_blend_tolerance() {
        let ini = |code: &str| {
            format!("[TRAJ]\nLINEAR_UNITS = inch\n[RS274NGC]\nRS274NGC_STARTUP_CODE = {code}\n")
        };
        let read = |code: &str| from_ini(&ini(code), "m.ini", &none).unwrap();
        // Inch: P0.001 in is 0.0254 mm.
        let f = read("G17 G20 G40 G64 P0.001 G90");
        assert!((f.machine.blend_tolerance_mm - 0.0254).abs() < 1e-12);
        assert!(
            f.toml.contains("m.ini:4 [RS274NGC]RS274NGC_STARTUP_CODE"),
            "{}",
            f.toml
        );
        assert_eq!(read("g17 g64p0.002").machine.blend_tolerance_mm, 0.0508);
        assert_eq!(read("G64 P0.01 G61.1").machine.blend_tolerance_mm, 0.0);
        let bare = read("G17 G64 G90");
        assert_eq!(
            bare.machine.blend_tolerance_mm,
            Machine::default().blend_tolerance_mm
        );
        assert!(bare.toml.contains("a bare G64"), "{}", bare.toml);
        assert_eq!(
            read("G17 G90").machine.blend_tolerance_mm,
            Machine::default().blend_tolerance_mm
        );
        assert_eq!(
            startup_path_mode("G61"),
            Some(StartMode::Exact("G61".into()))
        );
        assert_eq!(
            startup_path_mode("G64 P0 X1"),
            Some(StartMode::Blend(Some(0.0)))
        );
        assert_eq!(startup_path_mode("M3 S100"), None);
    }

    #[test]
    fn includes_and_mistakes_at_their_lines() {
        let inc = |name: &str| match name {
            "base.inc" => Ok("[TRAJ]\nLINEAR_UNITS = mm\nMAX_LINEAR_VELOCITY = 50\n".to_string()),
            "loop.inc" => Ok("#INCLUDE loop.inc\n".to_string()),
            "sub/a.inc" => Ok("#INCLUDE b.inc\n".to_string()),
            "sub/b.inc" => Ok("[TRAJ]\nMAX_LINEAR_VELOCITY = 20\n".to_string()),
            other => none(other),
        };
        let f = from_ini("#INCLUDE base.inc\n[KINS]\nJOINTS = 3\n", "m.ini", &inc).unwrap();
        assert_eq!(f.machine.max_feed_mm_per_min, 3000.0);
        assert!(f
            .toml
            .contains("from base.inc:3 [TRAJ]MAX_LINEAR_VELOCITY = 50 mm/s"));
        // An include within an include is looked for beside the file that names it.
        let f = from_ini("#INCLUDE sub/a.inc\n", "m.ini", &inc).unwrap();
        assert_eq!(f.machine.max_feed_mm_per_min, 1200.0);
        for (text, says) in [
            (
                "[TRAJ]\nMAX_LINEAR_VELOCITY = fast\n",
                "m.ini:2: [TRAJ]MAX_LINEAR_VELOCITY = fast: not a number",
            ),
            (
                "[TRAJ]\nLINEAR_UNITS = furlong\n",
                "m.ini:2: [TRAJ]LINEAR_UNITS = furlong",
            ),
            (
                "\n#INCLUDE gone.inc\n",
                "m.ini:2: #INCLUDE gone.inc: no such file",
            ),
            ("#INCLUDE loop.inc\n", "more than 8 deep"),
            (
                "[EMCMOT]\nSERVO_PERIOD = 50\n",
                "m.ini:2: [EMCMOT]SERVO_PERIOD = 50",
            ),
            ("[AXIS_X]\nMAX_VELOCITY = -1\n", "not one this control runs"),
            ("just words\n", "not a LinuxCNC INI file"),
        ] {
            let e = from_ini(text, "m.ini", &inc).unwrap_err();
            assert!(e.contains(says), "{text}: {e}");
        }
    }
}
