"""sim: Newton models more than one stage simulates.

The joint (`joint`: a part on one joint and its passive forces) is simulated by the jointed identification,
the diagnosis and `twin synth --engine newton`. The free and planar rollouts belong to identification (the
diagnosis reaches them through `pipelines.identify`); `twin synth` makes its held and pushed truths with its
own code and with MuJoCo, so that no convention shared by truth and fit can hide an error (docs/method.md).
"""
