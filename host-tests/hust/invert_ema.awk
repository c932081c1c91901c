# Undoes the exponential moving average (alpha = 0.05 per sample) applied
# to every temperature column of HUST profile 0 (see the data README):
# x[k] = (y[k] - 0.95 y[k-1]) / 0.05, rounded back onto the 0.1 degC grid
# (the rotor column is on no grid and is left unrounded). Other columns
# pass unchanged. Usage: awk -F, -f invert_ema.awk id_0.csv > id_0_raw.csv
BEGIN { OFS = "," }
NR == 1 {
  n = split("water_outlet bearing ambient rotor endwind_1 endwind_2 slotside slotopen slotbottom activewind_1 activewind_2 outer_yoke endcap", t, " ")
  for (i = 1; i <= n; i++) temp[t[i]] = 1
  for (c = 1; c <= NF; c++) { is_temp[c] = ($c in temp); name[c] = $c }
  print; next
}
{
  for (c = 1; c <= NF; c++) {
    y = $c + 0
    if (is_temp[c] && NR > 2) {
      x = (y - 0.95 * prev[c]) / 0.05
      if (name[c] != "rotor") x = sprintf("%.1f", x)
      prev[c] = y
      $c = x
    } else {
      prev[c] = y
    }
  }
  print
}
