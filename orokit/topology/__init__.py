"""orokit.topology"""
