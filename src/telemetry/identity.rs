//! The autopilot board's identity, where a log carries it: the airframe's name in a fleet's
//! history when the user gives none (a board moved to another airframe is the user's to map).
//!
//! One board gives one id whichever message carries it:
//! - ArduPilot's boot banner, sent as STATUSTEXT and logged as a DataFlash MSG: the board's
//!   name and its 96-bit MCU id as three 32-bit words in hex ("CubeOrange 003A002D 3138510F
//!   33393935"; `AP_HAL::Util::get_system_id`), read as `mcu 003A002D 3138510F 33393935`.
//! - MAVLink AUTOPILOT_VERSION: ArduPilot puts the same 12 bytes in `uid2`, each word's bytes
//!   least significant first (`get_system_id_unformatted`), read as the same `mcu ...`; `uid2`
//!   with anything past its 12th byte is no MCU id (ArduPilot's SITL puts the host's machine
//!   id there as text, the same for every simulated vehicle on a host) and gives none. A
//!   non-zero `uid` (64 bits, PX4) gives `uid XXXXXXXXXXXXXXXX`.
//! - A PX4 ULog's `sys_uuid` information message: the board's GUID as hex text
//!   (`board_get_px4_guid_formated`), read as `px4 ` and the hex digits in upper case. How it
//!   relates to the `uid` PX4 sends in AUTOPILOT_VERSION is not checked here, so a board seen
//!   both in a tlog and in a ULog may carry two ids (an airframes file maps both).

/// AUTOPILOT_VERSION's ids as text; `None` when neither is a board's id.
pub fn from_autopilot_version(uid: u64, uid2: &[u8]) -> Option<String> {
    if uid != 0 {
        return Some(format!("uid {uid:016X}"));
    }
    let (mcu, rest) = uid2.split_at(uid2.len().min(12));
    if mcu.len() < 12 || mcu.iter().all(|&b| b == 0) || rest.iter().any(|&b| b != 0) {
        return None;
    }
    let words: Vec<String> = mcu
        .chunks(4)
        .map(|w| format!("{:02X}{:02X}{:02X}{:02X}", w[3], w[2], w[1], w[0]))
        .collect();
    Some(format!("mcu {}", words.join(" ")))
}

/// A ULog's `sys_uuid` (hex text, trailing NULs allowed); `None` unless it is 8 to 64 hex
/// digits, not all zero.
pub fn from_px4_uuid(text: &str) -> Option<String> {
    let hex = text.trim_end_matches('\0').trim();
    let is_id = (8..=64).contains(&hex.len())
        && hex.chars().all(|c| c.is_ascii_hexdigit())
        && hex.chars().any(|c| c != '0');
    is_id.then(|| format!("px4 {}", hex.to_ascii_uppercase()))
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
    (named && ids.len() == 3 && ids.iter().all(is_word)).then(|| {
        let ids: Vec<String> = ids.iter().map(|w| w.to_ascii_uppercase()).collect();
        format!("mcu {}", ids.join(" "))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_banner_is_a_board_name_and_three_hex_words() {
        assert_eq!(
            from_banner("CUAVv5Nano 001A002F 30395113 33333539").as_deref(),
            Some("mcu 001A002F 30395113 33333539")
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

    /// The banner's words are the MCU id's 32-bit words; uid2 holds their bytes least
    /// significant first: both read as one id.
    #[test]
    fn uid2_and_the_banner_give_one_id() {
        let mut uid2 = [0u8; 18];
        uid2[..12].copy_from_slice(&[
            0x2F, 0x00, 0x1A, 0x00, 0x13, 0x51, 0x39, 0x30, 0x39, 0x35, 0x33, 0x33,
        ]);
        assert_eq!(
            from_autopilot_version(0, &uid2),
            from_banner("CUAVv5Nano 001A002F 30395113 33333539")
        );
    }

    #[test]
    fn a_ulog_s_uuid_is_its_hex_digits() {
        assert_eq!(
            from_px4_uuid("00020000000020373658375650100020002d\0").as_deref(),
            Some("px4 00020000000020373658375650100020002D")
        );
        assert_eq!(from_px4_uuid("0000000000000000"), None);
        assert_eq!(from_px4_uuid("not hex at all"), None);
        assert_eq!(from_px4_uuid("1234"), None);
    }

    #[test]
    fn zero_ids_and_a_simulator_s_host_id_are_none() {
        assert_eq!(from_autopilot_version(0, &[0; 18]), None);
        // ArduPilot SITL: the host's machine id as text, all 18 bytes.
        assert_eq!(from_autopilot_version(0, b"0c13df7d47f649a4bf"), None);
        assert_eq!(
            from_autopilot_version(0x1234, &[0; 18]).as_deref(),
            Some("uid 0000000000001234")
        );
    }
}
