//! The autopilot board's identity, where a log carries it: the airframe's name in a fleet's
//! history when the user gives none (a board moved to another airframe is the user's to map).
//!
//! - MAVLink AUTOPILOT_VERSION: `uid` (64 bits), else `uid2` (18 bytes); zero means none
//!   (SITL sends zeros).
//! - ArduPilot's boot banner, sent as STATUSTEXT and logged as a DataFlash MSG: the board's
//!   name and its 96-bit MCU id as three 8-digit hex words ("CubeOrange 003A002D 3138510F
//!   33393935"; `AP_HAL::Util::get_system_id`).

/// AUTOPILOT_VERSION's ids as text; `None` when both are zero.
pub fn from_autopilot_version(uid: u64, uid2: &[u8]) -> Option<String> {
    if uid != 0 {
        return Some(format!("uid {uid:016X}"));
    }
    uid2.iter().any(|&b| b != 0).then(|| {
        let hex: String = uid2.iter().map(|b| format!("{b:02X}")).collect();
        format!("uid2 {hex}")
    })
}

/// The board id in ArduPilot's boot banner: a name then exactly three 8-digit hex words.
pub fn from_banner(text: &str) -> Option<String> {
    let text = text.trim_end_matches('\0').trim();
    let words: Vec<&str> = text.split_whitespace().collect();
    let [name, ids @ ..] = words.as_slice() else {
        return None;
    };
    let is_word = |w: &&str| w.len() == 8 && w.chars().all(|c| c.is_ascii_hexdigit());
    let named = name.chars().any(|c| c.is_ascii_alphabetic()) && !is_word(name);
    (named && ids.len() == 3 && ids.iter().all(is_word)).then(|| words.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_banner_is_a_board_name_and_three_hex_words() {
        assert_eq!(
            from_banner("CUAVv5Nano 001A002F 30395113 33333539").as_deref(),
            Some("CUAVv5Nano 001A002F 30395113 33333539")
        );
        for other in [
            "ArduCopter V4.1.3 (2fb939a1)",
            "ChibiOS: 45395b6a",
            "u-blox 1 HW: 00080000 SW: EXT CORE 3.01 (107900)",
            "Board 001A002F 30395113",
            "001A002F 001A002F 30395113 33333539",
            "Board 001A002F 30395113 3333353Z",
            "",
        ] {
            assert_eq!(from_banner(other), None, "{other}");
        }
    }

    #[test]
    fn autopilot_version_ids_of_zero_are_none() {
        assert_eq!(from_autopilot_version(0, &[0; 18]), None);
        assert_eq!(
            from_autopilot_version(0x1234, &[0; 18]).as_deref(),
            Some("uid 0000000000001234")
        );
        assert_eq!(
            from_autopilot_version(0, &[0xAB, 0, 1]).as_deref(),
            Some("uid2 AB0001")
        );
    }
}
