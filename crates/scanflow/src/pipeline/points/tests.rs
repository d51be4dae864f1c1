use super::*;

#[test]
fn bucketing_by_key_is_the_stable_sort() {
    // Runs, repeats far apart and a lone key; and the empty cell.
    let ks: Vec<CellKey> = [5u32, 5, 2, 7, 7, 7, 2, 5, 0, 9, 2, 2, 7]
        .iter()
        .map(|&x| CellKey::new(4, [x, x % 3, 1]))
        .collect();
    for keys in [&ks[..], &ks[..1], &[][..]] {
        let (order, ranges) = bucket_by_key(keys);
        let mut want: Vec<u32> = (0..keys.len() as u32).collect();
        want.sort_by_key(|&i| (keys[i as usize], i));
        assert_eq!(order, want);
        assert_eq!(ranges, runs(want.len(), |j| keys[want[j] as usize]));
    }
}
