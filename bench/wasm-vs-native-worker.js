// Dedicated module worker of the wasm-vs-native bench: loads the given wasm package
// (www/pkg built by scripts/build-web.sh, or another build) and runs one `bench_step1`
// (timed inside wasm with performance.now(); loading and compiling are not timed).
self.onmessage = async (ev) => {
  const { pkgUrl, workload, m, iters, seed } = ev.data;
  try {
    const mod = await import(pkgUrl);
    await mod.default();
    const result = mod.bench_step1(workload, m, iters, BigInt(seed));
    self.postMessage({ result });
  } catch (e) {
    self.postMessage({ error: e instanceof Error ? e.message : String(e) });
  }
};
