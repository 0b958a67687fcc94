"""orokit.synthesis"""
