"""Validation of the trial methods: truth models written apart from them, and the coverage studies that feed
their data to the methods and count how often the stated intervals hold.

Nothing here is a method a user's result comes from: it checks `rimless.analysis.inference` (and the importer,
`rimless.analysis.kinematics`) against wheels and labs it was not fitted with.

The truth models (`critical_truth`, `floquet_truth`, `leg_truth`, `er_truth`) and their Vicon writer
(`vicon_writer`) import nothing from the methods or the importer; `er_truth` (the ER wheel, the default truth of
every ER study) imports nothing of the simulator either. The studies: `importer_coverage` (``rimless trials
coverage``, the default: truth exports through the importer), `coverage` (``--truth pendulum``),
`calibrate_coverage` (``rimless trials coverage --of calibrate``), `adequacy_coverage` (``rimless trials
adequacy-coverage``), `floquet_coverage` (``rimless trials floquet-coverage``), `leg_fit_coverage` (``rimless trials
leg-fit-coverage``), `slope_coverage` (``rimless trials slope-coverage``: the importer's slope interval); run with
``python -m``: `hub_offset_study` (the hub marker's offset and its 2 x 2), `impact_noise_study` (the adequacy
check's impact-time noise) and `impact_sd_study` (the importer's per-impact time sd).

May import: rimless.analysis.io, kinematics, inference, examples; rimless.sim (truth dynamics);
rimless.progress; numpy, scipy, pandas.
"""
