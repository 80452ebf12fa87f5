//! The settings' two flash pages, A and B, written alternately, so that a power cut during
//! `save` never costs the settings saved before.
//!
//! Each page holds one record ([`crate::settings`]) with a sequence number. A save:
//!
//! 1. reads both pages and finds the newest valid record ([`PageState`], [`choose`]);
//! 2. writes the *other* page ([`plan`]: erase, then program the record with the next
//!    sequence number, wrapping), never the page that holds the newest valid record;
//! 3. reads the written page back and decodes it: only a record that verifies (same bytes,
//!    no ECC error, decodes to the settings and sequence number written) counts. Until then
//!    the old record stays the newest valid one, untouched, and it is never erased: the
//!    next save writes over whichever page is then the older.
//!
//! At boot the valid record with the newest sequence number wins (compared in serial-number
//! arithmetic, so the wrap from `u32::MAX` to 0 keeps the order); a page that is torn (a
//! flash ECC double error, or a CRC mismatch) or refused is reported with the page used
//! instead ([`Boot::report`]: `warn settings: page B torn (flash ECC error), using page A
//! (seq 41)`). The defaults are used only when neither page holds a valid record.
//!
//! The flash itself is behind [`PageFlash`]: the firmware's register sequence
//! (`firmware/src/flash.rs`), or the host tests' model with a power cut at any operation.

use crate::dispatch::{self, Reply};
use crate::settings::{
    LoadError, Settings, RECORD_LEN, SETTINGS_ADDR, SETTINGS_PAGE_BYTES, SETTINGS_PAGE_NUMBER,
};

/// One of the two settings pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Page {
    /// Bank 2, page 126 ([`SETTINGS_ADDR`]).
    A,
    /// Bank 2, page 127, right after A.
    B,
}

impl Page {
    /// Both pages, A first.
    pub const BOTH: [Page; 2] = [Page::A, Page::B];

    /// The other page.
    pub const fn other(self) -> Page {
        match self {
            Page::A => Page::B,
            Page::B => Page::A,
        }
    }

    /// Its start address.
    pub const fn addr(self) -> u32 {
        SETTINGS_ADDR + self.index() as u32 * SETTINGS_PAGE_BYTES
    }

    /// Its page number within bank 2 (FLASH_CR.PNB).
    pub const fn number(self) -> u8 {
        SETTINGS_PAGE_NUMBER + self.index() as u8
    }

    /// 0 for A, 1 for B.
    pub const fn index(self) -> usize {
        match self {
            Page::A => 0,
            Page::B => 1,
        }
    }

    /// `A` or `B`.
    pub const fn name(self) -> &'static str {
        match self {
            Page::A => "A",
            Page::B => "B",
        }
    }
}

/// What reading one page gave: its record area, and whether a flash ECC double error was
/// seen while reading it (a double word torn by a power cut; the bytes then read are not
/// to be trusted, whatever their CRC says).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageRead {
    /// The record area as read.
    pub record: [u8; RECORD_LEN],
    /// A flash ECC double error in this page.
    pub ecc_error: bool,
}

/// What a page holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PageState {
    /// A valid record, with its sequence number.
    Valid(Settings, u32),
    /// Erased: nothing was written here (or only the erase of a save completed).
    Blank,
    /// A flash ECC double error: a save cut by a power loss.
    Torn,
    /// Something else, refused as a whole (a CRC mismatch is a torn or corrupted record).
    Refused(LoadError),
}

impl PageState {
    /// The state of a page as read.
    pub fn of(read: &PageRead) -> PageState {
        if read.ecc_error {
            return PageState::Torn;
        }
        match Settings::decode_record(&read.record) {
            Ok((s, seq)) => PageState::Valid(s, seq),
            Err(LoadError::Blank) => PageState::Blank,
            Err(e) => PageState::Refused(e),
        }
    }

    /// The sequence number of a valid record.
    pub fn seq(&self) -> Option<u32> {
        match self {
            PageState::Valid(_, seq) => Some(*seq),
            _ => None,
        }
    }

    /// Neither valid nor blank: worth a warning.
    pub fn is_bad(&self) -> bool {
        matches!(self, PageState::Torn | PageState::Refused(_))
    }
}

/// Whether sequence number `a` is newer than `b`: serial-number arithmetic (RFC 1982
/// style) on u32, so 0 follows `u32::MAX`. Only two records are ever compared, one save
/// apart, so the half-range limit is never near.
pub const fn newer(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

/// The page holding the newest valid record, and its sequence number.
pub fn newest(states: &[PageState; 2]) -> Option<(Page, u32)> {
    match (states[0].seq(), states[1].seq()) {
        (Some(a), Some(b)) if newer(b, a) => Some((Page::B, b)),
        (Some(a), _) => Some((Page::A, a)),
        (None, Some(b)) => Some((Page::B, b)),
        (None, None) => None,
    }
}

/// Where the next save goes and with which sequence number: the page that does *not* hold
/// the newest valid record, one past its number (wrapping); with no valid record, page A
/// with sequence number 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
    /// The page to erase and write.
    pub page: Page,
    /// The new record's sequence number.
    pub seq: u32,
}

/// The next save's [`Plan`] for the pages as they are.
pub fn plan(states: &[PageState; 2]) -> Plan {
    match newest(states) {
        Some((p, seq)) => Plan {
            page: p.other(),
            seq: seq.wrapping_add(1),
        },
        None => Plan {
            page: Page::A,
            seq: 1,
        },
    }
}

/// What the boot found: the settings to use, where they came from, and both pages' states
/// (for the report).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Boot {
    /// The settings in use: the newest valid record's, or the defaults.
    pub settings: Settings,
    /// The page and sequence number they came from (`None`: the defaults).
    pub from: Option<(Page, u32)>,
    /// Page A's and B's states.
    pub states: [PageState; 2],
}

/// The boot's choice: the valid record with the newest sequence number, else the
/// defaults.
pub fn choose(states: [PageState; 2]) -> Boot {
    let from = newest(&states);
    let settings = match from {
        Some((p, _)) => match states[p.index()] {
            PageState::Valid(s, _) => s,
            _ => Settings::defaults(),
        },
        None => Settings::defaults(),
    };
    Boot {
        settings,
        from,
        states,
    }
}

impl Boot {
    /// Whether a saved set was lost or refused (a page neither valid nor blank).
    pub fn warning(&self) -> bool {
        self.states.iter().any(PageState::is_bad)
    }

    /// The boot's lines about the settings, one per finding:
    /// - `settings loaded from flash (page A, seq 41)`;
    /// - `warn settings: page B torn (flash ECC error), using page A (seq 41)`, or
    ///   `... page B refused: <why>, using ...` for any other bad page;
    /// - `settings: defaults (nothing saved)` with both pages blank;
    /// - with no valid record but a bad page: `warn settings in flash refused: page A
    ///   <why>` per bad page, then `warn settings: defaults in use, drive idle`.
    pub fn report<R: Reply>(&self, out: &mut R) {
        match self.from {
            Some((p, seq)) => {
                let other = self.states[p.other().index()];
                if other.is_bad() {
                    out.put(b"warn settings: page ");
                    out.put(p.other().name().as_bytes());
                    put_state(out, &other);
                    out.put(b", using page ");
                } else {
                    out.put(b"settings loaded from flash (page ");
                }
                out.put(p.name().as_bytes());
                out.put(if other.is_bad() {
                    b" (seq ".as_slice()
                } else {
                    b", seq ".as_slice()
                });
                put_u32(out, seq);
                out.line(b")");
            }
            None if !self.warning() => out.line(b"settings: defaults (nothing saved)"),
            None => {
                for p in Page::BOTH {
                    let st = self.states[p.index()];
                    if st.is_bad() {
                        out.put(b"warn settings in flash refused: page ");
                        out.put(p.name().as_bytes());
                        put_state(out, &st);
                        out.end();
                    }
                }
                out.line(b"warn settings: defaults in use, drive idle");
            }
        }
    }
}

/// ` torn (flash ECC error)` or ` refused: <why>` of a bad page.
fn put_state<R: Reply>(out: &mut R, st: &PageState) {
    match st {
        PageState::Torn => out.put(b" torn (flash ECC error)"),
        PageState::Refused(e) => {
            out.put(b" refused: ");
            out.put(e.as_str().as_bytes());
            if let LoadError::Invalid(se) = e {
                dispatch::setting_error(out, se);
            }
        }
        PageState::Valid(..) | PageState::Blank => {}
    }
}

fn put_u32<R: Reply>(out: &mut R, mut v: u32) {
    let mut buf = [0u8; 10];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    out.put(&buf[i..]);
}

/// The two settings pages as the flash holds them.
pub trait PageFlash {
    /// Why a write failed.
    type Error: Copy;
    /// Reads page `page`'s record area (and whether an ECC double error was seen in it).
    fn read(&mut self, page: Page) -> PageRead;
    /// Erases `page`, then programs `record` at its start. Must never touch the other
    /// page.
    fn write(&mut self, page: Page, record: &[u8; RECORD_LEN]) -> Result<(), Self::Error>;
}

/// Why a save failed. The record saved before is still the newest valid one either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SaveError<E> {
    /// The erase or the programming failed.
    Flash(E),
    /// The written page does not read back as the record (or an ECC error in it).
    Verify,
}

/// Both pages' states as the flash holds them.
pub fn scan<F: PageFlash>(f: &mut F) -> [PageState; 2] {
    Page::BOTH.map(|p| PageState::of(&f.read(p)))
}

/// The boot: both pages read, the newest valid record chosen.
pub fn load<F: PageFlash>(f: &mut F) -> Boot {
    choose(scan(f))
}

/// Saves `s`: the page not holding the newest valid record is erased and written with the
/// next sequence number, then read back and decoded. Returns where it went.
pub fn save<F: PageFlash>(f: &mut F, s: &Settings) -> Result<Plan, SaveError<F::Error>> {
    let next = plan(&scan(f));
    let record = s.encode(next.seq);
    f.write(next.page, &record).map_err(SaveError::Flash)?;
    let back = f.read(next.page);
    if back.ecc_error
        || back.record != record
        || PageState::of(&back) != PageState::Valid(*s, next.seq)
    {
        return Err(SaveError::Verify);
    }
    Ok(next)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::settings::field_index;
    use proptest::prelude::*;
    use std::string::String;

    /// What a power cut leaves of the double word (or, for an erase, of each double word
    /// of the page) being written.
    #[derive(Clone, Copy, Debug)]
    enum Cut {
        /// The operation had not changed anything yet.
        Before,
        /// It had completed.
        After,
        /// Half-written bits that fail the flash's ECC (a double error on read).
        Torn(u8),
        /// Half-written bits that happen to pass the ECC (mixed old and new bits): only
        /// the record's CRC can tell.
        Garbled(u8),
    }

    /// The two pages' record areas, with the ECC state of each double word and a power
    /// cut at operation `cut_at` (1-based: each erase and each double word programmed is
    /// one operation).
    #[derive(Clone, Debug)]
    struct Model {
        pages: [[u8; RECORD_LEN]; 2],
        ecc: [[bool; RECORD_LEN / 8]; 2],
        ops: u32,
        cut_at: Option<(u32, Cut)>,
        /// The power failed: nothing runs after it.
        dead: bool,
        /// Operations per page, to check the other page is never touched.
        touched: [u32; 2],
    }

    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    struct PowerCut;

    impl Model {
        fn new() -> Self {
            Model {
                pages: [[0xFF; RECORD_LEN]; 2],
                ecc: [[false; RECORD_LEN / 8]; 2],
                ops: 0,
                cut_at: None,
                dead: false,
                touched: [0; 2],
            }
        }

        /// Power back on (the flash keeps its contents; nothing is cut any more).
        fn reboot(&mut self) {
            self.dead = false;
            self.cut_at = None;
            self.ops = 0;
        }

        /// One operation: double word `dw` of page `p` programmed with `new`; a cut
        /// leaves it as `Cut` says.
        fn op(&mut self, p: usize, dw: usize, new: [u8; 8]) -> Result<(), PowerCut> {
            self.ops += 1;
            self.touched[p] += 1;
            let cut = match self.cut_at {
                Some((at, cut)) if at == self.ops => cut,
                _ => {
                    self.pages[p][8 * dw..8 * dw + 8].copy_from_slice(&new);
                    self.ecc[p][dw] = false;
                    return Ok(());
                }
            };
            self.half(p, dw, new, cut);
            self.dead = true;
            Err(PowerCut)
        }

        fn half(&mut self, p: usize, dw: usize, new: [u8; 8], cut: Cut) {
            let old = &mut self.pages[p][8 * dw..8 * dw + 8];
            match cut {
                Cut::Before => {}
                Cut::After => {
                    old.copy_from_slice(&new);
                    self.ecc[p][dw] = false;
                }
                Cut::Torn(mask) | Cut::Garbled(mask) => {
                    for (o, n) in old.iter_mut().zip(new) {
                        *o = (*o & mask) | (n & !mask);
                    }
                    self.ecc[p][dw] = matches!(cut, Cut::Torn(_));
                }
            }
        }
    }

    impl PageFlash for Model {
        type Error = PowerCut;
        fn read(&mut self, page: Page) -> PageRead {
            let p = page.index();
            PageRead {
                record: self.pages[p],
                ecc_error: self.ecc[p].iter().any(|&e| e),
            }
        }
        fn write(&mut self, page: Page, record: &[u8; RECORD_LEN]) -> Result<(), PowerCut> {
            let p = page.index();
            // the erase: one operation over the whole page; a cut leaves every double
            // word of it as `Cut` says
            self.ops += 1;
            self.touched[p] += 1;
            match self.cut_at {
                Some((at, cut)) if at == self.ops => {
                    for dw in 0..RECORD_LEN / 8 {
                        self.half(p, dw, [0xFF; 8], cut);
                    }
                    self.dead = true;
                    return Err(PowerCut);
                }
                _ => {
                    self.pages[p] = [0xFF; RECORD_LEN];
                    self.ecc[p] = [false; RECORD_LEN / 8];
                }
            }
            for dw in 0..RECORD_LEN / 8 {
                let mut new = [0u8; 8];
                new.copy_from_slice(&record[8 * dw..8 * dw + 8]);
                self.op(p, dw, new)?;
            }
            Ok(())
        }
    }

    /// A save through the model with the power cut as given, then the power back on:
    /// whether the save completed.
    fn cut_save(m: &mut Model, s: &Settings, cut: Option<(u32, Cut)>) -> bool {
        m.ops = 0;
        m.cut_at = cut;
        let ok = save(m, s).is_ok();
        m.reboot();
        ok
    }

    /// A valid, distinct settings set for save number `n`.
    fn nth(n: u32) -> Settings {
        let i = field_index(b"limits.current_limit").unwrap();
        Settings::defaults()
            .set(i, 3.0 + (n % 150) as f32 * 0.01)
            .unwrap()
    }

    struct Text(String);
    impl Reply for Text {
        fn put(&mut self, t: &[u8]) {
            self.0.push_str(core::str::from_utf8(t).unwrap());
        }
        fn end(&mut self) {
            self.0.push('\n');
        }
    }

    fn report(b: &Boot) -> String {
        let mut t = Text(String::new());
        b.report(&mut t);
        t.0
    }

    #[test]
    fn pages_are_bank_2_pages_126_and_127() {
        assert_eq!(Page::A.addr(), 0x0807_F000);
        assert_eq!(Page::B.addr(), 0x0807_F800);
        assert_eq!((Page::A.number(), Page::B.number()), (126, 127));
        assert_eq!(Page::A.other(), Page::B);
        assert_eq!(Page::B.other(), Page::A);
    }

    #[test]
    fn sequence_numbers_compare_across_the_wrap() {
        assert!(newer(2, 1));
        assert!(!newer(1, 2));
        assert!(!newer(5, 5));
        assert!(newer(0, u32::MAX));
        assert!(newer(3, u32::MAX - 2));
        assert!(!newer(u32::MAX, 0));
        let v = |seq| PageState::Valid(Settings::defaults(), seq);
        assert_eq!(newest(&[v(u32::MAX), v(0)]), Some((Page::B, 0)));
        assert_eq!(newest(&[v(0), v(u32::MAX)]), Some((Page::A, 0)));
        assert_eq!(
            plan(&[v(u32::MAX), PageState::Blank]),
            Plan {
                page: Page::B,
                seq: 0
            }
        );
        assert_eq!(
            plan(&[PageState::Torn, PageState::Blank]),
            Plan {
                page: Page::A,
                seq: 1
            }
        );
        assert_eq!(
            plan(&[PageState::Torn, v(9)]),
            Plan {
                page: Page::A,
                seq: 10
            }
        );
    }

    /// Saves alternate between the pages, each one past the last; the old record is
    /// never touched by the save that replaces it; the boot reads the newest.
    #[test]
    fn saves_alternate_and_the_newest_wins() {
        let mut m = Model::new();
        assert_eq!(load(&mut m).from, None);
        assert_eq!(
            report(&load(&mut m)),
            "settings: defaults (nothing saved)\n"
        );
        for n in 1..=5u32 {
            let before = m.clone();
            let p = save(&mut m, &nth(n)).unwrap();
            assert_eq!(p.seq, n);
            assert_eq!(p.page, if n % 2 == 1 { Page::A } else { Page::B });
            // the page holding the previous record was not touched
            assert_eq!(
                m.touched[p.page.other().index()],
                before.touched[p.page.other().index()]
            );
            assert_eq!(
                m.pages[p.page.other().index()],
                before.pages[p.page.other().index()]
            );
            let b = load(&mut m);
            assert_eq!(b.settings, nth(n));
            assert_eq!(b.from, Some((p.page, n)));
            assert!(!b.warning());
        }
        assert_eq!(
            report(&load(&mut m)),
            "settings loaded from flash (page A, seq 5)\n"
        );
    }

    #[test]
    fn a_torn_page_is_reported_with_the_page_used() {
        let mut m = Model::new();
        for n in 1..=41 {
            save(&mut m, &nth(n)).unwrap();
        }
        // the 42nd save (to page B) cut during its third double word, torn
        assert!(!cut_save(&mut m, &nth(42), Some((4, Cut::Torn(0x5A)))));
        let b = load(&mut m);
        assert_eq!(b.settings, nth(41));
        assert_eq!(b.states[1], PageState::Torn);
        assert_eq!(
            report(&b),
            "warn settings: page B torn (flash ECC error), using page A (seq 41)\n"
        );
        // garbled without an ECC error: the CRC refuses it
        assert!(!cut_save(&mut m, &nth(42), Some((4, Cut::Garbled(0x5A)))));
        let b = load(&mut m);
        assert_eq!(b.settings, nth(41));
        assert_eq!(
            report(&b),
            "warn settings: page B refused: CRC mismatch (corrupted record), using page A (seq 41)\n"
        );
        // the next save goes to the bad page again, and succeeds
        let p = save(&mut m, &nth(42)).unwrap();
        assert_eq!(
            p,
            Plan {
                page: Page::B,
                seq: 42
            }
        );
        assert_eq!(load(&mut m).settings, nth(42));
        assert!(!load(&mut m).warning());
    }

    #[test]
    fn nothing_valid_is_reported_per_page() {
        let mut m = Model::new();
        assert!(!cut_save(&mut m, &nth(1), Some((1, Cut::Torn(0x0F)))));
        let b = load(&mut m);
        assert_eq!(b.from, None);
        assert_eq!(b.settings, Settings::defaults());
        assert_eq!(
            report(&b),
            "warn settings in flash refused: page A torn (flash ECC error)\n\
             warn settings: defaults in use, drive idle\n"
        );
        // an intact record that today's validation refuses: named, with the rule
        let mut m = Model::new();
        let mut rec = Settings::defaults().encode(3);
        let i = field_index(b"loops.flux_current").unwrap();
        rec[12 + 4 * i..16 + 4 * i].copy_from_slice(&50f32.to_le_bytes());
        let at = crate::settings::CRC;
        let crc = crate::settings::crc32(&rec[..at]);
        rec[at..at + 4].copy_from_slice(&crc.to_le_bytes());
        m.pages[1] = rec;
        assert_eq!(
            report(&load(&mut m)),
            "warn settings in flash refused: page B refused: stored value refused \
             (loops.flux_current: must be below current_limit)\n\
             warn settings: defaults in use, drive idle\n"
        );
    }

    /// A save whose read-back differs is an error, and the old record stays in use.
    #[test]
    fn a_save_that_does_not_verify_fails_and_keeps_the_old_record() {
        struct Stuck(Model);
        impl PageFlash for Stuck {
            type Error = PowerCut;
            fn read(&mut self, p: Page) -> PageRead {
                self.0.read(p)
            }
            fn write(&mut self, p: Page, r: &[u8; RECORD_LEN]) -> Result<(), PowerCut> {
                self.0.write(p, r)?;
                // one bit that did not program
                self.0.pages[p.index()][20] |= 0x10;
                Ok(())
            }
        }
        let mut m = Model::new();
        save(&mut m, &nth(1)).unwrap();
        let mut s = Stuck(m);
        assert_eq!(save(&mut s, &nth(2)), Err(SaveError::Verify));
        assert_eq!(load(&mut s.0).settings, nth(1));
    }

    fn cut() -> impl Strategy<Value = Cut> {
        prop_oneof![
            Just(Cut::Before),
            Just(Cut::After),
            any::<u8>().prop_map(Cut::Torn),
            any::<u8>().prop_map(Cut::Garbled),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]
        /// After a power cut at any operation of any save (the erase, or any double word),
        /// whatever the cut leaves, the boot loads either the settings saved before or the
        /// ones being saved: the defaults only while nothing was ever saved. Saves without a
        /// cut load exactly what they saved. The sequence numbers start anywhere, so the
        /// wrap from u32::MAX to 0 is crossed.
        #[test]
        fn a_cut_at_any_operation_loads_the_old_or_the_new_settings(
            start in prop_oneof![Just(u32::MAX - 3), Just(0u32), any::<u32>()],
            start_on_b in any::<bool>(),
            saves in proptest::collection::vec(
                (any::<bool>(), 1u32..=1 + (RECORD_LEN / 8) as u32, cut()), 1..12),
        ) {
            let mut m = Model::new();
            // a record saved before, anywhere in the sequence space
            let mut last: Option<Settings> = None;
            if start != 0 {
                let first = nth(1000);
                m.pages[start_on_b as usize] = first.encode(start);
                last = Some(first);
            }
            for (n, (cut_here, at, how)) in saves.into_iter().enumerate() {
                let s = nth(n as u32);
                let saved = cut_save(&mut m, &s, cut_here.then_some((at, how)));
                let b = load(&mut m);
                if saved {
                    prop_assert_eq!(b.settings, s);
                } else {
                    let old = last.unwrap_or_else(Settings::defaults);
                    prop_assert!(b.settings == s || b.settings == old,
                        "cut at op {} ({:?}) of save {}: neither old nor new", at, how, n);
                    // the defaults only if nothing was ever saved
                    if b.from.is_none() {
                        prop_assert!(last.is_none());
                    }
                }
                // the chosen record is one of the pages' valid ones, the newest
                if let Some((p, seq)) = b.from {
                    prop_assert_eq!(b.states[p.index()].seq(), Some(seq));
                    if let Some(o) = b.states[p.other().index()].seq() {
                        prop_assert!(newer(seq, o));
                    }
                }
                if b.from.is_some() {
                    last = Some(b.settings);
                }
            }
        }
    }
}
