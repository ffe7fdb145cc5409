"""Tool-tip calibration: the ball centre in the flange frame and an honest sample error bound.

Modules, in the order a calibration uses them: ``pivot`` (coarse tip from poses about one point),
``table`` (table plane and frame), ``tip`` (fine tip from tilted table taps), ``bound`` (sample error
bound proposal), ``calibrate`` (all steps from recorded poses), ``store`` (the ``fixwizard.tip/1`` YAML)
and ``plans`` (flange poses for the robot-driven steps). ``robust`` finds taps that do not belong;
``spin`` refuses tilted taps whose tip depends on the flange's spin about the tool axis.
"""
