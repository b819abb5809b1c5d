//! Signals: SIGINT/SIGTERM/SIGHUP remove this process's unfinished output files before it
//! dies (`motu_package::atomic` registers them); SIGBUS — a memory-mapped package or scene
//! file truncated or overwritten while mapped — becomes an error naming the file instead of a
//! bare "bus error".

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by the SIGBUS handler so the cleanup thread exits with status 1 without a second line.
static BUS_ERROR: AtomicBool = AtomicBool::new(false);

/// Installs both; call first thing in `main`.
pub fn install() {
    install_termination_cleanup();
    install_sigbus_handler();
}

fn install_termination_cleanup() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = match signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!("signal handlers not installed ({e}): an interrupted command may leave .motu-tmp files (a later write to the same output removes them)");
            return;
        }
    };
    std::thread::Builder::new()
        .name("motu-signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                let cleanup = motu_package::atomic::remove_registered_temp_outputs();
                if BUS_ERROR.load(Ordering::SeqCst) {
                    std::process::exit(1);
                }
                let name = match sig {
                    SIGINT => "SIGINT",
                    SIGTERM => "SIGTERM",
                    _ => "SIGHUP",
                };
                eprintln!("motu: {}", interrupted_message(name, &cleanup));
                // Die of the signal, as the shell and parent processes expect.
                let _ = signal_hook::low_level::emulate_default_handler(sig);
                std::process::exit(128 + sig);
            }
        })
        .ok();
}

/// What an interrupted command says: the unfinished outputs it removed, and any output it had
/// already completed before the signal (kept: it is whole and valid), so a late interrupt never
/// reads as if the old file were still there.
fn interrupted_message(signal: &str, c: &motu_package::atomic::SignalCleanup) -> String {
    let mut msg = format!(
        "interrupted by {signal}; removed {} unfinished output file(s)",
        c.removed
    );
    if !c.completed.is_empty() {
        let names: Vec<String> = c
            .completed
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        msg.push_str(&format!(
            "; already completed before the signal, and kept: {}",
            names.join(", ")
        ));
    }
    msg
}

fn install_sigbus_handler() {
    // SAFETY: `on_sigbus` only calls async-signal-safe functions (open, read, write, close,
    // kill, nanosleep, _exit) and touches no locks or allocations; the sigaction struct is
    // fully initialised (zeroed, then the handler, flags and an empty mask).
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigbus as *const () as usize;
        sa.sa_flags = libc::SA_SIGINFO;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGBUS, &sa, std::ptr::null_mut());
    }
}

/// A fixed buffer that formats without allocating (signal handlers must not allocate).
struct Msg {
    buf: [u8; 1024],
    len: usize,
}

impl Msg {
    fn push(&mut self, s: &[u8]) {
        let n = s.len().min(self.buf.len() - self.len);
        self.buf[self.len..self.len + n].copy_from_slice(&s[..n]);
        self.len += n;
    }

    fn push_u64(&mut self, mut v: u64) {
        let mut digits = [0u8; 20];
        let mut i = digits.len();
        loop {
            i -= 1;
            digits[i] = b'0' + (v % 10) as u8;
            v /= 10;
            if v == 0 {
                break;
            }
        }
        self.push(&digits[i..]);
    }
}

fn parse_hex(s: &[u8]) -> Option<u64> {
    if s.is_empty() || s.len() > 16 {
        return None;
    }
    let mut v = 0u64;
    for &c in s {
        let d = (c as char).to_digit(16)?;
        v = (v << 4) | u64::from(d);
    }
    Some(v)
}

/// One `/proc/self/maps` line: the mapped file and the file offset of `addr`, if it maps it.
fn maps_line_match(line: &[u8], addr: u64) -> Option<(&[u8], u64)> {
    let mut fields = line.split(|&b| b == b' ').filter(|f| !f.is_empty());
    let range = fields.next()?;
    let dash = range.iter().position(|&b| b == b'-')?;
    let (start, end) = (parse_hex(&range[..dash])?, parse_hex(&range[dash + 1..])?);
    if !(start..end).contains(&addr) {
        return None;
    }
    let _perms = fields.next()?;
    let offset = parse_hex(fields.next()?)?;
    let _dev = fields.next()?;
    let _inode = fields.next()?;
    // The path is the rest of the line after the inode column (it may contain spaces).
    let path_start = nth_field_start(line, 5)?;
    Some((&line[path_start..], offset + (addr - start)))
}

/// Byte index where the `n`th (0-based) space-separated field of `line` starts.
fn nth_field_start(line: &[u8], n: usize) -> Option<usize> {
    let mut field = 0;
    let mut in_field = false;
    for (i, &b) in line.iter().enumerate() {
        if b == b' ' {
            in_field = false;
        } else if !in_field {
            if field == n {
                return Some(i);
            }
            field += 1;
            in_field = true;
        }
    }
    None
}

/// Looks `addr` up in `/proc/self/maps` and writes the message into `msg`.
fn describe_fault(addr: u64, msg: &mut Msg) {
    let mut found = false;
    // SAFETY: plain open/read/close of a procfs file into stack buffers.
    let fd = unsafe { libc::open(c"/proc/self/maps".as_ptr(), libc::O_RDONLY) };
    if fd >= 0 {
        let mut line = [0u8; 4608];
        let mut line_len = 0usize;
        let mut chunk = [0u8; 4096];
        'read: loop {
            // SAFETY: `chunk` is a valid writable buffer of its length.
            let n = unsafe { libc::read(fd, chunk.as_mut_ptr().cast(), chunk.len()) };
            if n <= 0 {
                break;
            }
            for &b in &chunk[..n as usize] {
                if b != b'\n' {
                    if line_len < line.len() {
                        line[line_len] = b;
                        line_len += 1;
                    }
                    continue;
                }
                if let Some((path, offset)) = maps_line_match(&line[..line_len], addr) {
                    if path.first() == Some(&b'/') {
                        msg.push(b"error: bus error reading ");
                        msg.push(path);
                        msg.push(b" at byte ");
                        msg.push_u64(offset);
                        msg.push(b": the file was truncated or overwritten while motu had it memory-mapped. Inputs (packages, scene and PLY files) must not change while a command reads them; restore the file (or re-import the package) and run the command again.\n");
                        found = true;
                    }
                    break 'read;
                }
                line_len = 0;
            }
        }
        // SAFETY: `fd` was opened above.
        unsafe { libc::close(fd) };
    }
    if !found {
        msg.push(b"error: bus error (SIGBUS) at address ");
        msg.push_u64(addr);
        msg.push(
            b": a memory-mapped input was probably truncated or overwritten while motu read it.\n",
        );
    }
}

extern "C" fn on_sigbus(_sig: libc::c_int, info: *mut libc::siginfo_t, _ctx: *mut libc::c_void) {
    // SAFETY: the kernel passes a valid siginfo for an SA_SIGINFO handler.
    let addr = unsafe { (*info).si_addr() } as u64;
    let mut msg = Msg {
        buf: [0; 1024],
        len: 0,
    };
    describe_fault(addr, &mut msg);
    // SAFETY: write(2) to stderr from a stack buffer; kill/nanosleep/_exit are
    // async-signal-safe. Returning would re-run the faulting load, so this never returns:
    // the cleanup thread (woken by SIGTERM) removes temp files and exits 1; if it cannot,
    // the process exits here after a grace period.
    unsafe {
        libc::write(2, msg.buf.as_ptr().cast(), msg.len);
        BUS_ERROR.store(true, Ordering::SeqCst);
        libc::kill(libc::getpid(), libc::SIGTERM);
        let ts = libc::timespec {
            tv_sec: 5,
            tv_nsec: 0,
        };
        libc::nanosleep(&ts, std::ptr::null_mut());
        libc::_exit(1);
    }
}

#[cfg(test)]
mod tests;
