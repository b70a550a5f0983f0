//! `tensorholo::io::remove_temporary_files`, alone in its test binary: it removes the temporary files of every
//! write in progress in the process, which would break the writes of tests running beside it.

use std::fs;

use ndarray::Array2;
use tensorholo::io::write_f32_npy;
use tensorholo::HoloError;

#[test]
fn an_interrupt_handler_can_remove_the_write_in_progress() {
    // `remove_temporary_files` (what `holo` calls on Ctrl-C) sees the temporary file of a write in progress:
    // called from inside the write, it removes it; the output never appears under its final name.
    let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("interrupt");
    fs::remove_dir_all(&dir).ok();
    fs::create_dir_all(&dir).unwrap();
    let path = dir.join("big.npy");
    let mut seen = 0;
    let result = tensorholo::io::write_f32_npy_streaming(&path, &[4, 1000], 1000, |start, buf| {
        buf.fill(1.0);
        if start == 2000 {
            let tmp: Vec<_> = fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            assert!(
                tmp.iter().any(|n| n.starts_with(".big.npy.tmp-")),
                "{tmp:?}"
            );
            seen = tensorholo::io::remove_temporary_files();
            return Err(HoloError::Internal("interrupted".into()));
        }
        Ok(())
    });
    assert!(result.is_err());
    assert!(seen >= 1);
    assert!(!path.exists());
    assert_eq!(fs::read_dir(&dir).unwrap().count(), 0);
    // Completed writes are no longer listed.
    write_f32_npy(&path, Array2::<f32>::zeros((2, 2)).view()).unwrap();
    tensorholo::io::remove_temporary_files();
    assert!(path.exists());
}
